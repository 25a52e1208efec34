"""Two network_monitor nodes on one real master, each the other's peer over 127.0.0.1: the cloud one runs
the iperf3 server on a free port, the robot one probes it on request. Parameters from
config/network_monitor.yaml with a few changes."""
import math
import os
import shutil
import subprocess

import pytest

from cnr_harness import free_port, wait_until

rospy = pytest.importorskip('rospy')
pytestmark = pytest.mark.skipif(shutil.which('iperf3') is None, reason='iperf3 is not installed')


def params(workspace, **changes):
    from cnr_params import load_yaml
    out = dict(load_yaml(os.path.join(workspace, 'config', 'network_monitor.yaml')), **changes)
    for key in [k for k, v in changes.items() if v is None]:
        del out[key]
    return out


@pytest.fixture(scope='module')
def monitors(ros, workspace):
    port = free_port()
    common = dict(peer_address='127.0.0.1', echo_rate=10.0, publish_rate=5.0, probe_interval=0.0, probe_method='iperf3',
                  probe_seconds=1, probe_omit=0, probe_bytes=2000000, probe_timeout=5.0)
    ros.master.call('setParam', '/nm_robot', params(workspace, name='robot', peer='cloud', iperf3_server=False,
                                                    probe_port=port, **common))
    ros.master.call('setParam', '/nm_cloud', params(workspace, name='cloud', peer='robot', iperf3_server=True,
                                                    iperf3_server_port=port, **common))
    procs = [ros.master.run(['rosrun', 'network_monitor', 'network_monitor', f'__name:={n}'], n)
             for n in ('nm_robot', 'nm_cloud')]
    yield port
    for proc in procs:
        ros.master.stop_child(proc)
    for n in ('nm_robot', 'nm_cloud'):
        ros.master.call('deleteParam', f'/{n}')


def latest_profile(host, timeout=30.0):
    from cnr_msgs.msg import NetworkProfile
    got = []
    sub = rospy.Subscriber(f'/network_monitor/{host}/network_profile', NetworkProfile, got.append)
    try:
        return wait_until(lambda: next((m for m in reversed(got) if m.alive and math.isfinite(m.rtt)), None),
                          timeout, f'an alive profile from {host}')
    finally:
        sub.unregister()


@pytest.mark.parametrize('host,peer', [('robot', 'cloud'), ('cloud', 'robot')])
def test_both_monitors_publish_alive_profiles_with_a_finite_rtt(monitors, host, peer):
    from cnr_msgs.msg import NetworkProfile
    p = latest_profile(host)
    assert p.peer == peer and p.alive and 0 < p.rtt < 1.0 and math.isfinite(p.rtt_spread)
    assert 0.0 <= p.loss <= 1.0 and p.interface == 'lo'
    assert p.a_bw_method == NetworkProfile.NONE and math.isnan(p.a_bw) and p.probe_bytes == 0


def test_profile_now_with_a_probe_measures_a_bw(monitors):
    from cnr_msgs.msg import NetworkProfile
    from cnr_msgs.srv import ProfileNow
    rospy.wait_for_service('/nm_robot/profile_now', timeout=30)
    call = rospy.ServiceProxy('/nm_robot/profile_now', ProfileNow)
    r = wait_until(lambda: (lambda x: x if x.success else None)(call(probe=True)), 30, 'a successful probe')
    p = r.profile
    # paced to the byte cap on loopback: 2 MB in 1 s (16 Mbit/s), in iperf3's 128 KiB writes
    assert p.a_bw > 0 and p.a_bw_method == NetworkProfile.PROBE and 1000000 <= p.probe_bytes <= 2000000 + 131072
    assert p.a_bw <= 1.25 * 16e6 and p.a_bw_age < 2.0
    assert math.isfinite(p.r_bw) and p.r_bw > 0
    quiet = call(probe=False)
    assert quiet.success and quiet.profile.probe_bytes == p.probe_bytes


def test_a_probe_without_server_fails_cleanly(monitors):
    from cnr_msgs.srv import ProfileNow
    rospy.wait_for_service('/nm_cloud/profile_now', timeout=30)
    r = rospy.ServiceProxy('/nm_cloud/profile_now', ProfileNow)(probe=True)   # the robot runs no server
    assert not r.success and 'iperf3' in r.message


def test_missing_parameter_exits_2_naming_it(ros, workspace):
    ros.master.call('setParam', '/nm_bad', params(workspace, probe_bytes=None))
    try:
        r = subprocess.run(['rosrun', 'network_monitor', 'network_monitor', '__name:=nm_bad'],
                           env=ros.master.env, capture_output=True, text=True, timeout=60)
    finally:
        ros.master.call('deleteParam', '/nm_bad')
    assert r.returncode == 2
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and '/nm_bad: probe_bytes: missing' in lines[0], r.stderr
