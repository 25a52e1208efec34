"""``catkin_make install`` and the corridor mission from the install space alone (no devel space, no source
tree on ROS_PACKAGE_PATH): launch files find config/ and maps/ through cnr_config's installed copies."""
from __future__ import annotations

import json
import os
import subprocess

import pytest

from cnr_harness import RosMaster, wait_until

pytest.importorskip('rospy')

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _bare_env() -> dict:
    """A shell's environment with no workspace sourced (as a new user's)."""
    return {'HOME': os.environ.get('HOME', '/root'), 'PATH': '/usr/sbin:/usr/bin:/sbin:/bin'}


def _install_env(prefix: str) -> dict:
    """The environment ``source PREFIX/setup.bash`` gives a shell with nothing else sourced."""
    out = subprocess.run(['bash', '-c', f'source {prefix}/setup.bash && env -0'], env=_bare_env(), check=True,
                         capture_output=True, timeout=60).stdout.decode()
    return dict(item.split('=', 1) for item in out.split('\0') if '=' in item)


@pytest.fixture(scope='module')
def install_prefix(tmp_path_factory):
    root = tmp_path_factory.mktemp('install_space')
    build, prefix = str(root / 'build'), str(root / 'install')
    # its own build and devel spaces (catkin_make would otherwise rebuild the devel space the suite runs from),
    # and no workspace sourced, so the install space overlays nothing
    r = subprocess.run(['catkin_make', '--source', WS, '--build', build, f'-DCATKIN_DEVEL_PREFIX={root}/devel',
                        f'-DCMAKE_INSTALL_PREFIX={prefix}', '-DPYTHON_EXECUTABLE=/usr/bin/python3',
                        '-DCATKIN_ENABLE_TESTING=OFF', 'install'],
                       cwd=str(root), env=_bare_env(), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    return prefix


def test_install_space_holds_config_maps_and_programs(install_prefix):
    share = os.path.join(install_prefix, 'share')
    assert os.path.isfile(os.path.join(share, 'cnr_config', 'config', 'robot.yaml'))
    assert not os.path.islink(os.path.join(share, 'cnr_config', 'config'))
    assert os.path.isfile(os.path.join(share, 'cnr_config', 'maps', 'corridor.pgm'))
    for program in ('cnr_sim/simulator', 'cnr_mission/mission_monitor', 'cnr_mission/check_scenario',
                    'cnr_bringup/cnr_launch', 'mfg/mfg'):
        assert os.access(os.path.join(install_prefix, 'lib', program), os.X_OK), program
    assert os.path.isfile(os.path.join(install_prefix, 'CATKIN_IGNORE'))   # never crawled as a second copy


def test_mission_runs_from_the_install_space(install_prefix, tmp_path):
    env = _install_env(install_prefix)
    assert WS not in env.get('ROS_PACKAGE_PATH', ''), env.get('ROS_PACKAGE_PATH')
    report = str(tmp_path / 'report')
    with RosMaster(use_sim_time=True, env=env) as master:
        proc = master.run(['rosrun', 'cnr_bringup', 'cnr_launch', '--until', 'mission_monitor', 'cnr_mission',
                           'mission.launch', 'monitor_required:=false', 'real_time_factor:=5',
                           f'report_dir:={report}', f'store:={report}/store.tsv'], log_name='installed_mission')
        wait_until(lambda: not proc.alive(), 600, 'the mission from the install space to end')
        out = proc.output()
    assert proc.returncode == 0, out[-3000:]
    with open(os.path.join(report, 'summary.json')) as stream:
        summary = json.load(stream)
    assert summary['found'] is True and summary['hotspot']['cell'] == 19, summary
