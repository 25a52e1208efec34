"""The corridor monitoring mission on a real master with real nodes: finds the heaters' cell, writes the
report, a restart of local_mapcell_manager mid-mission loses no stored measurement, and the run ends by
itself, quietly (as launch_scripts/run_mission.sh runs it: cnr_launch --until mission_monitor)."""
import json
import os
import re
import subprocess

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

HEATER_CELL = 19            # col 8, row 1: x 8..9, y 0..1 in config/scenarios/corridor.yaml


@pytest.fixture(scope='module')
def mission(ros, workspace, tmp_path_factory):
    report = tmp_path_factory.mktemp('report')
    proc = ros.master.run(['rosrun', 'cnr_bringup', 'cnr_launch', '--until', 'mission_monitor',
                           'cnr_mission', 'mission.launch', 'monitor_required:=false', 'scenario:=corridor',
                           f'map:={workspace}/maps/corridor.yaml', 'real_time_factor:=4',
                           f'report_dir:={report}', f'store:={report}/store.tsv'], log_name='mission')
    yield proc, report
    proc.stop()


def stored_lines(path):
    with open(path) as f:
        return [l for l in f.read().split('\n')[1:] if l]


def test_mission_finds_hotspot_and_survives_a_restart(mission, ros):
    from cnr_msgs.msg import Hotspot
    proc, report = mission
    store = os.path.join(report, 'store.tsv')
    wait_until(lambda: os.path.exists(store) and len(stored_lines(store)) >= 60 or not proc.alive(), 240,
             '60 stored measurements')
    assert proc.alive(), proc.output()[-3000:]
    before = len(stored_lines(store))
    subprocess.run(['rosnode', 'kill', '/local_mapcell_manager'], env=ros.master.env, check=True,
                   capture_output=True, timeout=30)
    # roslaunch respawns it; it must come back with every stored measurement
    from cnr_msgs.srv import GetMeasurements

    def reloaded():
        try:
            rospy.wait_for_service('local_mapcell_manager/get_measurements', 1.0)
            res = rospy.ServiceProxy('local_mapcell_manager/get_measurements', GetMeasurements)(-1)
            return res if len(res.measurements) >= before else None
        except (rospy.ROSException, rospy.ServiceException):
            return None
    res = wait_until(reloaded, 60, 'local_mapcell_manager back with its measurements')
    numbers = [m.header.seq for m in res.measurements]
    assert numbers[:before] == list(range(1, before + 1))

    summary_path = os.path.join(report, 'summary.json')
    wait_until(lambda: os.path.exists(summary_path) or not proc.alive() and not os.path.exists(summary_path), 600,
             'the mission report')
    summary = json.load(open(summary_path))
    assert summary['found'] is True, summary
    assert summary['hotspot']['cell'] == HEATER_CELL
    assert summary['sim_time_to_find'] < 400.0
    assert summary['distance_driven'] > 8.0 and summary['battery_used_percent'] > 0
    # the mission as a task (the network-aware decision's T_task, B_task): to the hotspot, not to the end
    task = summary['task']
    assert task['mission_status'] == 'completed' and task['t_task'] == pytest.approx(summary['sim_time_to_find'])
    # B_task on the robot computer's pack (laptop_charge), to the hotspot: less than that pack gave in the mission
    computer = summary['computer_battery']
    assert 0 < task['b_task'] < computer['used_percent'] / 100.0, (task, computer)
    rows = open(os.path.join(report, 'measurements.tsv')).read().splitlines()
    assert rows[0].split('\t')[:5] == ['measurement', 'time', 'x', 'y', 'temperature']
    assert len(rows) - 1 == summary['measurements_taken'] >= before
    numbers = [int(r.split('\t')[0]) for r in rows[1:]]
    assert numbers == list(range(1, len(numbers) + 1))           # nothing lost across the restart
    assert os.path.getsize(os.path.join(report, 'mapcells.png')) > 10000

    # the launch ends by itself once the monitor is done: exit 0, no red lines, no traceback
    wait_until(lambda: not proc.alive(), 120, 'the mission launch to end after its report')
    out = proc.output()
    assert proc.returncode == 0, out[-3000:]
    red = re.search(r'.*(?:REQUIRED process|escalating to SIG|required SIGKILL|Shutdown errors|Traceback).*', out)
    assert red is None, out[max(0, red.start() - 1500):red.end() + 2500]
