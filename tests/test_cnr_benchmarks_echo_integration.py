"""echo_client against echo_monitor on a real master, its parameters from config/echo_client.yaml."""
import os
import subprocess

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


def run_client(ros, workspace, **changes):
    from cnr_params import load_yaml
    params = dict(load_yaml(os.path.join(workspace, 'config', 'echo_client.yaml')), **changes)
    for key in [k for k, v in changes.items() if v is None]:
        del params[key]
    ros.master.call('setParam', '/echo_client', params)
    try:
        return subprocess.run(['rosrun', 'cnr_benchmarks', 'echo_client', '__name:=echo_client'],
                              env=ros.master.env, capture_output=True, text=True, timeout=120)
    finally:
        ros.master.call('deleteParam', '/echo_client')


@pytest.fixture(scope='module')
def monitor(ros):
    proc = ros.master.run(['rosrun', 'cnr_benchmarks', 'echo_monitor'], 'echo_monitor')
    wait_until(lambda: '/rtt/echo' in {s for s, _ in ros.master.call('getSystemState')[2]}, 60,
               'the echo_monitor service', proc)
    yield proc
    ros.master.stop_child(proc)


@pytest.mark.parametrize('mode', ['topic', 'service_persistent'])
def test_client_measures_and_writes_its_samples(ros, workspace, monitor, tmp_path, mode):
    out = tmp_path / f'{mode}.tsv'
    r = run_client(ros, workspace, mode=mode, samples=3, interval=0.0, output=str(out))
    assert r.returncode == 0, r.stderr
    rows = out.read_text().splitlines()[1:]
    assert [int(line.split('\t')[0]) for line in rows] == [1, 2, 3]
    assert all(float(line.split('\t')[1]) > 0 for line in rows)


def test_missing_parameter_exits_2_naming_it(ros, workspace):
    r = run_client(ros, workspace, timeout=None)
    assert r.returncode == 2
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and '/echo_client: timeout: missing' in lines[0], r.stderr
