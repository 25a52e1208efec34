"""The testbed as root: namespaces joined by the emulator, live changes, outage, nothing left behind."""
import os
import re
import signal
import subprocess
import time

import pytest

from cnr_harness import wait_until

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='needs root (network namespaces and TUN devices)')

NAME = f'tbt{os.getpid() % 10000}'


def script(workspace, *args):
    return subprocess.run([f'{workspace}/launch_scripts/testbed.sh', '--name', NAME, *args], capture_output=True,
                          text=True, timeout=60)


def ping_rtt(count=5):
    r = subprocess.run(['ip', 'netns', 'exec', f'{NAME}-robot', 'ping', '-c', str(count), '-i', '0.2', '-W', '2',
                        '10.77.0.2'], capture_output=True, text=True, timeout=60)
    m = re.search(r'= [\d.]+/([\d.]+)/', r.stdout)
    return float(m.group(1)) if m else None


def leftovers():
    ns = subprocess.run(['ip', 'netns'], capture_output=True, text=True).stdout
    procs = subprocess.run(['pgrep', '-af', 'cnr_testbed.emulator'], capture_output=True, text=True).stdout
    return [l for l in ns.splitlines() + procs.splitlines() if NAME in l]


@pytest.fixture
def testbed(workspace):
    r = script(workspace, 'up')
    assert r.returncode == 0, r.stderr
    yield
    script(workspace, 'down')
    assert not leftovers()


def test_delay_live_change_and_outage(testbed, workspace):
    base = ping_rtt()
    assert base is not None and base < 20
    assert script(workspace, 'set', '--delay', '25').returncode == 0
    assert 48 < ping_rtt() < 60                    # 2 x 25 ms (a loose bound, not a timing target)
    assert script(workspace, 'set', '--outage', 'on').returncode == 0
    assert ping_rtt(3) is None
    assert script(workspace, 'set', '--outage', 'off', '--delay', '0').returncode == 0
    assert ping_rtt() is not None
    status = script(workspace, 'status').stdout
    assert 'lost' in status and NAME in status
    r = script(workspace, 'set', '--delay', '-4')
    assert r.returncode != 0


def test_each_host_has_the_configured_network_settings(testbed, workspace):
    from cnr_params import load_yaml
    from cnr_testbed.netns import has_sysctl
    testbed_cfg = load_yaml(f'{workspace}/config/testbed.yaml')['testbed']
    settings = dict(testbed_cfg['sysctl'])
    settings.update({k: v for k, v in testbed_cfg['sysctl_if_available'].items() if has_sysctl(k)})
    assert settings
    for side in ('robot', 'cloud'):
        for key, value in settings.items():
            r = subprocess.run(['ip', 'netns', 'exec', f'{NAME}-{side}', 'sysctl', '-n', key], capture_output=True,
                               text=True, timeout=30)
            assert r.stdout.strip() == str(value), (side, key, r.stdout, r.stderr)


def test_the_link_emulator_forwards_at_its_priority(testbed, workspace):
    from cnr_params import load_yaml
    nice = load_yaml(f'{workspace}/config/testbed.yaml')['testbed']['emulator_nice']
    sup = int(open(f'/run/cnr_testbed/{NAME}.pid').read())
    child = int(subprocess.run(['pgrep', '-P', str(sup)], capture_output=True, text=True).stdout.split()[0])
    assert os.getpriority(os.PRIO_PROCESS, child) == nice


def test_down_leaves_nothing_and_sigkill_is_cleaned_up(workspace):
    assert script(workspace, 'up').returncode == 0
    sup = int(open(f'/run/cnr_testbed/{NAME}.pid').read())
    child = int(subprocess.run(['pgrep', '-P', str(sup)], capture_output=True, text=True).stdout.split()[0])
    os.kill(child, signal.SIGKILL)                 # a crash of the emulator
    wait_until(lambda: not leftovers(), 15, 'the supervisor to remove namespaces after a crash')
    assert script(workspace, 'up').returncode == 0
    assert script(workspace, 'down').returncode == 0
    assert not leftovers()
    assert not os.path.exists(f'/run/cnr_testbed/{NAME}.sock')
