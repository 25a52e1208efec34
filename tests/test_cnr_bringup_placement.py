"""The placement catalog (config/placements.yaml, cnr_bringup.placement): hosts, allow-lists, relays, errors."""
import os
import subprocess

import pytest
import yaml

from cnr_bringup.placement import launch_args, load_catalog
from cnr_params.config import ConfigError

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CATALOG = os.path.join(WS, 'config', 'placements.yaml')


@pytest.fixture(scope='module')
def catalog():
    return load_catalog(CATALOG)


def test_named_placements_of_the_issue_exist(catalog):
    for name in ('all_robot', 'move_base_cloud', 'paper_normal', 'paper_network_aware'):
        catalog.placement(name)


def test_hosts_of_each_named_placement(catalog):
    assert catalog.placement('all_robot').modules_on('cloud') == []
    assert catalog.placement('move_base_cloud').modules_on('cloud') == ['move_base']
    assert catalog.placement('paper_normal').modules_on('cloud') == ['global_goal_manager', 'mfg']
    aware = catalog.placement('paper_network_aware')
    assert aware.modules_on('cloud') == ['global_goal_manager']
    assert aware.host('mfg') == 'robot'
    for name in catalog.named:            # the body and the observer never move
        p = catalog.placement(name)
        assert p.host('simulator') == p.host('kestrel_driver') == p.host('mission_monitor') == 'robot'


def test_allow_lists_follow_the_placement(catalog):
    allr = catalog.placement('all_robot')
    assert allr.allow('topics') == sorted(catalog.always['topics'])     # sim time, monitors, migration protocol
    assert allr.allow('services') == sorted(catalog.always['services'])
    mb = catalog.placement('move_base_cloud')
    for t in ('/scan', '/odom', '/tf', '/mobile_base/commands/velocity', '/move_base/*', '/clock'):
        assert t in mb.allow('topics')
    assert '/merged_measurements' not in mb.allow('topics')
    aware = catalog.placement('paper_network_aware')
    assert aware.allow('services') == sorted(['/global_goal_manager/*', *catalog.always['services']])
    assert '/cell_states' in aware.allow('topics') and '/mapcell_measurements' not in aware.allow('topics')
    normal = catalog.placement('paper_normal')
    assert '/mapcell_measurements' in normal.allow('topics') and '/move_base/*' in normal.allow('topics')
    assert '/global_goal_manager/*' not in normal.allow('services')      # GG and MFG are both on the cloud


def test_store_and_forward_replaces_the_direct_topic(catalog):
    cloud = catalog.placement('monitoring_cloud')
    assert [s.topic for s in cloud.relayed()] == ['/merged_measurements']
    assert '/merged_measurements' not in cloud.allow('topics')
    assert '/store_forward/merged_measurements/*' in cloud.allow('topics')
    assert catalog.placement('paper_normal').relayed() == []


def test_launch_args(catalog):
    args = launch_args(catalog.placement('paper_normal'), 'cloud')
    assert 'mfg:=true' in args and 'global_goal_manager:=true' in args and 'move_base:=false' in args
    assert not any(a.startswith('simulator') for a in args)


def test_placement_file_and_differences(catalog, tmp_path):
    f = tmp_path / 'mine.yaml'
    f.write_text('move_base: cloud\nmfg: cloud\n')
    p = catalog.placement(str(f))
    assert p.name == 'mine' and p.modules_on('cloud') == ['move_base', 'mfg']
    assert p.differs(catalog.placement('move_base_cloud')) == {'mfg': ('cloud', 'robot')}


@pytest.mark.parametrize('content, field', [
    ('move_bas: cloud\n', 'move_bas'),
    ('move_base: moon\n', 'move_base'),
    ('simulator: cloud\n', 'simulator'),
])
def test_bad_placement_file_names_the_field(catalog, tmp_path, content, field):
    f = tmp_path / 'bad.yaml'
    f.write_text(content)
    with pytest.raises(ConfigError) as exc:
        catalog.placement(str(f))
    assert str(f) in str(exc.value) and field in str(exc.value)


def test_unknown_name(catalog):
    with pytest.raises(ConfigError, match="no placement named 'nope'"):
        catalog.placement('nope')


def test_bad_catalog(tmp_path):
    data = yaml.safe_load(open(CATALOG))
    data['placements']['broken'] = {'mfg': 'mars'}
    f = tmp_path / 'placements.yaml'
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r'placements\.broken\.mfg'):
        load_catalog(str(f))


def test_cli_show_and_error():
    out = subprocess.run(['rosrun', 'cnr_bringup', 'placement', 'show', 'move_base_cloud'], capture_output=True,
                         text=True)
    assert out.returncode == 0 and 'cloud  move_base' in out.stdout
    bad = subprocess.run(['rosrun', 'cnr_bringup', 'placement', 'show', 'nope'], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and 'Traceback' not in bad.stderr


def test_managed_modules_cross_from_either_host_and_are_started_by_the_agents(catalog):
    p = catalog.placement('paper_network_aware').managed_by(['mfg', 'global_goal_manager', 'move_base'])
    topics = p.allow('topics')
    for t in ('/move_base/*', '/scan', '/mobile_base/commands/velocity', '/cell_states', '/mfg/*', '/hotspot'):
        assert t in topics, t                        # either side may hold them at run time
    assert '/global_goal_manager/*' in p.allow('services')
    args = launch_args(p, 'cloud') + launch_args(p, 'robot')
    assert 'mfg:=true' not in args and 'global_goal_manager:=true' not in args and 'move_base:=true' not in args
    assert 'merger:=true' in launch_args(p, 'robot')
    lmm = catalog.placement('monitoring_cloud')
    assert lmm.relayed()
    # a movable store may be on the cloud at any time: the relay carries its input wherever it starts
    for name in ('monitoring_cloud', 'all_robot'):
        managed = catalog.placement(name).managed_by(['local_mapcell_manager'])
        assert [s.topic for s in managed.relayed()] == ['/merged_measurements']
        assert '/merged_measurements' not in managed.allow('topics')
        assert '/store_forward/merged_measurements/*' in managed.allow('topics')
    with pytest.raises(ValueError, match='not movable'):
        p.managed_by(['kestrel_driver'])
