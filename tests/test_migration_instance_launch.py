"""The agent's launch resolution (migration_manager.instance_launch): the one node of a module instance, its
command line, environment and parameters as roslaunch would run it; a real master for the parameters."""
import os
import xmlrpc.client

import pytest

from cnr_harness import RosMaster
from migration_manager.instance_launch import LaunchError, resolve

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(WS, 'config')


def _args(module, host='robot'):
    return [f'{module}:=true', 'migration_role:=standby', f'migration_host:={host}', f'config_dir:={CONFIG}',
            f'scenario_file:={CONFIG}/scenarios/corridor.yaml', f'map:={WS}/maps/corridor.yaml',
            'store:=/tmp/cnr_test_store.tsv']


def test_a_module_resolves_to_its_one_node_with_the_launch_environment_and_parameters():
    nl = resolve('cnr_mission', 'modules.launch', 'move_base', _args('move_base', 'cloud'), 'http://127.0.0.1:1/')
    assert nl.node == '/move_base'
    assert os.path.basename(nl.argv[0]) == 'move_base' and '__name:=move_base' in nl.argv
    assert nl.env['CNR_CALLERID_SUFFIX'] == 'cloud'                 # modules.launch's <env> for managed instances
    assert nl.env['ROS_MASTER_URI'] == 'http://127.0.0.1:1/'
    assert nl.params['/move_base/DWAPlannerROS/max_vel_x'] > 0   # move_base.yaml, loaded by the launch
    assert any(k.startswith('/move_base/migration/') for k in nl.params)    # config/migration.yaml


def test_a_launch_without_exactly_one_node_for_the_module_is_refused():
    args = [a for a in _args('move_base') if not a.startswith('move_base:=')]      # no module enabled
    with pytest.raises(LaunchError, match='launches 0 nodes'):
        resolve('cnr_mission', 'modules.launch', 'move_base', args, 'http://127.0.0.1:1/')
    with pytest.raises(LaunchError, match='nope.launch'):
        resolve('cnr_mission', 'nope.launch', 'move_base', _args('move_base'), 'http://127.0.0.1:1/')


def test_the_parameters_reach_the_master_in_one_multicall():
    nl = resolve('cnr_mission', 'modules.launch', 'mfg', _args('mfg'), 'http://127.0.0.1:1/')
    with RosMaster() as master:
        nl.set_params(master.uri, 5.0)
        proxy = xmlrpc.client.ServerProxy(master.uri)
        for key, value in nl.params.items():
            code, _msg, got = proxy.getParam('/test', key)
            assert code == 1 and got == value, key
