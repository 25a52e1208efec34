"""The robot CPU cap on this machine's real cgroups (root): the cap holds, usage is read, exit status and
network namespaces pass through, nothing is left behind, and the battery charges exactly the cgroup.

Skipped with the reason when not root or when no cpu cgroup is available.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time

import pytest
import yaml

from cnr_harness import wait_until
from cnr_testbed import cpucap
from cnr_testbed.core.cpucap import NoCgroup

PY = sys.executable
WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUSY = ('import sys, time\nt, c = time.monotonic(), time.process_time()\n'
        'while time.monotonic() - t < float(sys.argv[1]): pass\n'
        'print(time.process_time() - c, time.monotonic() - t)\n')


def _layout():
    if os.geteuid() != 0:
        return None, 'needs root (cgroups)'
    try:
        return cpucap.detect(), ''
    except NoCgroup as exc:
        return None, f'no cpu cgroup available: {exc}'


LAYOUT, WHY = _layout()
pytestmark = pytest.mark.skipif(LAYOUT is None, reason=WHY)


def cli(*args: str, timeout: float = 60.0, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([PY, '-m', 'cnr_testbed.cpucap', *args], capture_output=True, text=True, timeout=timeout,
                          **kw)


def leftovers(prefix: str):
    return [os.path.join(h, d) for h in LAYOUT.hierarchies() for d in os.listdir(h) if d.startswith(prefix)]


@pytest.fixture
def name():
    n = f'cnr_test_{os.getpid()}_{time.monotonic_ns() % 1000000}'
    yield n
    cli('remove', '--name', n, '--kill')
    assert not leftovers(n)


def test_quarter_cpu_cap_usage_and_removal(name):
    r = cli('create', '--name', name, '--cpus', '0.25', '--period-us', '10000')
    assert r.returncode == 0 and '0.25 CPU per 10000 us' in r.stdout, r.stderr
    r = cli('run', '--name', name, '--', PY, '-c', BUSY, '2.0')
    assert r.returncode == 0, r.stderr
    cpu, wall = map(float, r.stdout.split())
    assert 0.05 < cpu / wall <= 0.3, f'CPU share {cpu / wall:.3f} of one CPU under a 0.25 cap'
    cg = cpucap.CpuCgroup(LAYOUT, name)
    assert cg.usage_seconds() >= 0.9 * cpu
    st = json.loads(cli('status', '--name', name, '--json').stdout)
    assert st['cpus'] == 0.25 and st['period_us'] == 10000 and st['throttled'] > 0 and st['pids'] == []
    r = cli('remove', '--name', name)
    assert r.returncode == 0 and 'removed' in r.stdout
    assert not leftovers(name) and not cg.exists()


def test_remove_moves_or_kills_the_processes_left_inside(name):
    cg = cpucap.CpuCgroup(LAYOUT, name)
    cg.create(0.5, 10000)
    sleepers = [subprocess.Popen(cpucap.run_argv(['sleep', '30'], name)) for _ in range(2)]
    try:
        wait_until(lambda: len(cg.pids()) == 2, 20, 'two sleepers in the group')
        moved = cg.remove()
        assert sorted(moved) == sorted(p.pid for p in sleepers) and not cg.exists()
        assert all(p.poll() is None for p in sleepers)          # moved out, still running
        cg.create(0.5, 10000)
        cg.add(sleepers[0].pid)
        assert cg.remove(kill=True) == [sleepers[0].pid]
        assert sleepers[0].wait(10) == -9
    finally:
        for p in sleepers:
            p.kill()
            p.wait()


def test_exit_status_and_under_ip_netns_exec(name):
    ns = f'cnrcap{os.getpid() % 100000}'
    subprocess.run(['ip', 'netns', 'add', ns], check=True)
    try:
        r = subprocess.run(['ip', 'netns', 'exec', ns, PY, '-m', 'cnr_testbed.cpucap', 'run', '--name', name,
                            '--cpus', '0.5', '--', 'sh', '-c', 'cat /proc/self/cgroup; ip -o link; exit 7'],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 7, r.stderr
        assert f':cpu:/{name}' in r.stdout and 'lo:' in r.stdout and r.stderr == ''
    finally:
        subprocess.run(['ip', 'netns', 'delete', ns])
    r = cli('run', '--name', name, '--', 'no-such-command-here')
    assert r.returncode == 127 and 'no-such-command-here' in r.stderr


@pytest.mark.skipif(shutil.which('setpriv') is None, reason='setpriv (util-linux) missing')
def test_not_root_runs_the_command_uncapped():
    nobody = ['setpriv', '--reuid=65534', '--regid=65534', '--clear-groups']
    if subprocess.run(nobody + [PY, '-c', 'import cnr_testbed.cpucap'], capture_output=True).returncode != 0:
        pytest.skip('the workspace is not readable by nobody (e.g. a checkout under /root)')
    r = subprocess.run(['setpriv', '--reuid=65534', '--regid=65534', '--clear-groups', PY, '-m',
                        'cnr_testbed.cpucap', 'run', '--', 'sh', '-c', 'exit 3'], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 3
    assert r.stderr.strip() == 'cpucap: no cpu cgroup available (not root): running without the robot CPU cap'


def test_usage_reader_follows_removal_and_recreation(name):
    reader = cpucap.UsageReader(name)
    assert reader.read() is None and name in reader.problem
    cg = cpucap.CpuCgroup(LAYOUT, name)
    cg.create(0.5, 10000)
    assert reader.read() == 0.0
    assert cli('run', '--name', name, '--', PY, '-c', BUSY, '0.3').returncode == 0
    used = reader.read()
    assert used > 0.05 and used == pytest.approx(cg.usage_seconds())
    cg.remove()
    assert reader.read() is None
    cg.create(0.5, 10000)
    assert reader.read() == 0.0
    reader.close()


@pytest.fixture
def testbed():
    from cnr_testbed.api import Testbed
    from cnr_testbed.cli import overrides
    tb = Testbed(os.path.join(WS, 'config', 'testbed.yaml'), overrides(f'tcap{os.getpid() % 10000}'))
    with tb:
        yield tb
    assert not leftovers(tb.robot_cgroup)


def test_robot_side_capped_and_its_tun_device_counted(testbed):
    """testbed.sh robot runs in the robot's namespace inside its cgroup; psutil there sees the TUN device."""
    code = ('import subprocess, sys\nfrom cnr_sim.core.battery import NetMeter\n'
            'm, every = NetMeter(sys.argv[1]), NetMeter("")\nm.sample(); every.sample()\n'
            'subprocess.run(["ping", "-q", "-c", "5", "-i", "0.05", "-s", "1000", sys.argv[2]], check=True,'
            ' capture_output=True)\nprint(open("/proc/self/cgroup").read())\n'
            'print("bytes", m.sample(), every.sample())\n')
    r = subprocess.run([PY, '-m', 'cnr_testbed.cli', '--name', testbed.cfg.name, 'robot', '--', PY, '-c', code,
                        testbed.cfg.robot_dev, testbed.cloud_address], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f':cpu:/{testbed.robot_cgroup}' in r.stdout
    counted = [int(x) for x in r.stdout.split('bytes')[1].split()]
    assert counted[0] >= 5 * 2 * 1028 and counted[1] == counted[0]     # 5 pings of 1028-byte IP packets, both ways
    assert leftovers(testbed.robot_cgroup)          # the group exists while the testbed is up; down removes it


def test_battery_charges_exactly_the_robot_cgroup(ros, name):
    """Under load from itself, the simulator charges the CPU time of the robot's cgroup and nothing else, each
    second at the robot CPU's full-load power over the cgroup's limit (launch arg battery_cpu_capacity)."""
    import rospy
    from cnr_msgs.msg import BatteryEnergy
    cg = cpucap.CpuCgroup(LAYOUT, name)
    cg.create(0.25, 10000)
    msgs = []
    lock = threading.Lock()

    def on_energy(msg):
        with lock:
            msgs.append(msg)

    sub = rospy.Subscriber('battery/energy', BatteryEnergy, on_energy, queue_size=10)
    sim = ros.master.roslaunch('cnr_sim', 'simulator.launch', f'battery_cpu_cgroup:={name}',
                               'battery_cpu_capacity:=0.25')
    try:
        wait_until(lambda: msgs or not sim.alive(), 90, 'battery/energy from the simulator')
        assert sim.alive(), sim.output()[-2000:]
        r = cli('run', '--name', name, '--', PY, '-c', BUSY, '3.0')
        assert r.returncode == 0, r.stderr
        used = cg.usage_seconds()
        assert used > 0.3
        wait_until(lambda: msgs[-1].cpu_seconds >= 0.95 * used, 20, 'the cgroup CPU time charged')
        time.sleep(2.5)                                                    # more samples: nothing else is added
        last = msgs[-1]
        assert last.cpu_seconds == pytest.approx(used, abs=0.05), (last.cpu_seconds, used)
        with open(os.path.join(WS, 'config', 'battery.yaml')) as f:
            power = yaml.safe_load(f)['battery']['cpu_full_load_power']
        assert last.cpu == pytest.approx(power / 0.25 * last.cpu_seconds, rel=1e-6)
        assert last.total == pytest.approx(last.idle + last.motors + last.cpu + last.radio)
        assert last.idle > 0 and last.header.stamp.to_sec() > 0
    finally:
        sub.unregister()
        ros.master.stop_child(sim)
