"""How runs end: a bad scenario stops before anything is launched, a node's configuration error ends the
launch at once with exit 2 (never respawned), and Ctrl-C stops every node without escalation to SIGKILL.

Real rosmasters on free ports, real roslaunch (through cnr_bringup's cnr_launch) and real nodes.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import time

import pytest
import yaml

from cnr_harness import RosMaster, wait_until

pytest.importorskip('rospy')

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORRIDOR = os.path.join(WS, 'config', 'scenarios', 'corridor.yaml')
# what roslaunch prints when a node does not stop on SIGINT within its timeout or a required node dies, and
# a node's traceback
ESCALATION = re.compile(r'escalating to SIG(TERM|KILL)|required SIGKILL|Shutdown errors|REQUIRED process|Traceback')


def _scenario(tmp_path, edit) -> str:
    with open(CORRIDOR) as stream:
        data = yaml.safe_load(stream)
    edit(data)
    path = os.path.join(str(tmp_path), 'scenario.yaml')
    with open(path, 'w') as stream:
        yaml.safe_dump(data, stream)
    return path


def _mission_argv(scenario: str, report: str, *extra: str) -> list:
    return ['rosrun', 'cnr_bringup', 'cnr_launch', '--until', 'mission_monitor', 'cnr_mission', 'mission.launch',
            'monitor_required:=false', f'scenario_file:={scenario}', f'map:={WS}/maps/corridor.yaml',
            f'report_dir:={report}', f'store:={report}/store.tsv', *extra]


def test_a_node_configuration_error_ends_the_launch_with_exit_2_without_respawn(tmp_path):
    """The mapcell grid outside the map: local_mapcell_manager (respawn="true") exits 2 and the launch ends."""
    def grid_outside(data):
        data['mapcells']['min_x'] = 40.0
    scenario = _scenario(tmp_path, grid_outside)
    with RosMaster(use_sim_time=True) as master:
        proc = master.run(_mission_argv(scenario, str(tmp_path / 'report')), log_name='bad_grid')
        wait_until(lambda: not proc.alive(), 60, 'the launch to end after the configuration error')
        code = proc.returncode
        out = proc.output()
    assert code == 2, out[-3000:]
    assert 'local_mapcell_manager exited with a configuration error' in out, out[-3000:]
    assert 'mapcells' in out and 'outside the map' in out, out[-3000:]
    assert 'restarting process' not in out, out[-3000:]


def test_a_managed_move_base_with_a_bad_migration_setting_exits_2_at_once(tmp_path):
    """The error is found after init_node, with move_base's non-daemon threads running: the node still leaves at
    once, so its launch ends with status 2 (a migration agent's standby is then reported exited, and the
    migration that started it rolls back at once instead of waiting out the start timeout)."""
    cfg = tmp_path / 'config'
    subprocess.run(['cp', '-rL', os.path.join(WS, 'config'), str(cfg)], check=True)
    with open(cfg / 'migration.yaml') as f:
        mig = yaml.safe_load(f)
    del mig['control_nice']
    with open(cfg / 'migration.yaml', 'w') as f:
        yaml.safe_dump(mig, f)
    with RosMaster(use_sim_time=True) as master:
        proc = master.run(['rosrun', 'cnr_bringup', 'cnr_launch', 'cnr_mission', 'modules.launch', 'move_base:=true',
                           'migration_role:=standby', 'migration_host:=robot', f'config_dir:={cfg}',
                           f'map:={WS}/maps/corridor.yaml', f'scenario_file:={CORRIDOR}',
                           f'store:={tmp_path}/store.tsv'], log_name='bad_migration')
        wait_until(lambda: not proc.alive(), 60, 'the launch to end after the configuration error')
        code = proc.returncode
        out = proc.output()
    assert code == 2, out[-3000:]
    assert 'control_nice: missing' in out and 'move_base exited with a configuration error' in out, out[-3000:]


def test_ctrl_c_stops_every_node_without_escalation(tmp_path):
    """SIGINT to the launch's process group (a terminal's Ctrl-C) stops the whole mission quietly."""
    report = str(tmp_path / 'report')
    with RosMaster(use_sim_time=True) as master:
        proc = master.run(_mission_argv(CORRIDOR, report, 'real_time_factor:=2'), log_name='ctrl_c')
        nodes = {'/simulator', '/move_base', '/map_server', '/kestrel_driver', '/merger', '/local_mapcell_manager',
                 '/global_goal_manager', '/mfg', '/mission_monitor'}
        wait_until(lambda: nodes <= set(master.node_names()), 90, f'every mission node registered ({nodes})', proc)
        # the mission is moving: measurements are being stored
        wait_until(lambda: os.path.exists(f'{report}/store.tsv') and os.path.getsize(f'{report}/store.tsv') > 200,
                   120, 'stored measurements', proc)
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        wait_until(lambda: not proc.alive(), 60, 'the launch to stop after SIGINT')
        code = proc.returncode
        took = time.monotonic() - t0
        out = proc.output()
        left = [n for n in master.node_names() if n in nodes]
    assert not ESCALATION.search(out), out[-4000:]
    assert code == 130, out[-3000:]
    assert not left, f'still registered after the launch stopped: {left}'
    print(f'the mission stopped {took:.1f} s after SIGINT')
