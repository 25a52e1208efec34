"""The bridge under a flapping link (root): two real masters in the testbed's namespaces, two real bridges, real
nodes on both sides publishing, subscribing, serving and calling across, and a short seeded schedule of outages
(cuts and loss bursts; both directions, up only, down only; :mod:`cnr_testbed.core.flap`).

After every outage the invariant holds again soon after the link's return (median <= 1 s, each <= 2 s;
:mod:`multimaster_bridge.core.invariant`, polled by :class:`multimaster_bridge.watch.RestoreWatch`): each master's
registrations of the other host's nodes are exactly the other master's own registrations that the allow-lists let
across (each under ``/<peer>/<node>`` at the node's own URI), and a service both hosts provide is served by the newer
provider on both.
At the end a subscriber, a persistent service client and an actionlib client on each side are served across again,
with neither side restarted.

Run as a script (``tests/test_multimaster_bridge_flap.py SIDE OTHER``) this module is the test's node on one side.
"""
import json
import os
import statistics
import sys
import time

import pytest

NAME = f'flp{os.getpid() % 10000}'
ALLOW = ['/flap/*', '/clock']
SHARED = '/flap/shared'             # served on both hosts: the cloud's provider is the newer one
SEED, COUNT = 18, 8                 # cuts of 1.3-6.7 s (up only, down only, both) and loss bursts; ~41 s in all
# a longer measurement: BRIDGE_FLAP_SEED=7 BRIDGE_FLAP_COUNT=24 BRIDGE_FLAP_WIDE=1 (outages 0.2-15 s, gaps 0.5-20 s)
SEED = int(os.environ.get('BRIDGE_FLAP_SEED', SEED))
COUNT = int(os.environ.get('BRIDGE_FLAP_COUNT', COUNT))
WIDE = os.environ.get('BRIDGE_FLAP_WIDE', '') == '1'
RESTORE_LIMIT = 1.0                 # s after the link returns: the median of the checked outages
# any one outage: a machine loaded far beyond its two cores (load average 20) delays the bridges' processes
# themselves (one restore of 1.37 s in ten loaded runs); a registration not restored at all fails at 5 s
RESTORE_LIMIT_ANY = 2.0
SETTLE = 1.2                        # an outage is checked when the link stays up at least this long after it


# -- the node on each side ------------------------------------------------------------------------------------------
def peer_main(side: str, other: str) -> None:
    """Publishes ``/flap/<side>/says`` and subscribes the other side's; serves ``/flap/<side>/trigger``, SHARED and
    the action ``/flap/<side>/act``; calls the other side's service over one persistent connection and sends goals
    to its action server. On the robot it publishes /clock (wall time, 100 Hz); the cloud runs on that sim time and
    counts every step back of its clock (``clock_back``) and every ROSTimeMovedBackwardsException (``time_back``:
    what made the mission's mfg exit). Prints its counters as a JSON line twice a second."""
    import threading

    import actionlib
    import rospy
    from actionlib_msgs.msg import GoalStatus
    from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal, MoveBaseResult
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String
    from std_srvs.srv import Trigger, TriggerResponse

    rospy.init_node(f'flap_{side}')
    counts = dict(rx=0, call_ok=0, call_err=0, act_ok=0, act_err=0, clock_back=0, time_back=0)
    lock = threading.Lock()
    last_clock = [0.0]

    def bump(key: str) -> None:
        with lock:
            counts[key] += 1

    def on_clock(msg) -> None:
        t = msg.clock.to_sec()
        if t < last_clock[0]:
            bump('clock_back')
        last_clock[0] = max(last_clock[0], t)

    rospy.Subscriber(f'/flap/{other}/says', String, lambda _m: bump('rx'))
    pub = rospy.Publisher(f'/flap/{side}/says', String, queue_size=10)
    rospy.Service(f'/flap/{side}/trigger', Trigger, lambda _r: TriggerResponse(True, side))
    rospy.Service(SHARED, Trigger, lambda _r: TriggerResponse(True, side))
    server = actionlib.SimpleActionServer(f'/flap/{side}/act', MoveBaseAction, auto_start=False,
                                          execute_cb=lambda _g: server.set_succeeded(MoveBaseResult()))
    server.start()
    if side == 'robot':
        clock = rospy.Publisher('/clock', Clock, queue_size=10)

        def tick() -> None:
            while not rospy.is_shutdown():
                clock.publish(Clock(clock=rospy.Time.from_sec(time.time())))
                time.sleep(0.01)
        threading.Thread(target=tick, daemon=True).start()
    else:
        rospy.Subscriber('/clock', Clock, on_clock)

    def call_across() -> None:
        name, proxy = f'/flap/{other}/trigger', None
        while not rospy.is_shutdown():
            try:
                if proxy is None:
                    rospy.wait_for_service(name, timeout=1.0)
                    proxy = rospy.ServiceProxy(name, Trigger, persistent=True)
                bump('call_ok' if proxy().success else 'call_err')
            except (rospy.ServiceException, rospy.ROSException, OSError):
                bump('call_err')
            time.sleep(0.2)

    def act_across() -> None:
        client = actionlib.SimpleActionClient(f'/flap/{other}/act', MoveBaseAction)
        while not rospy.is_shutdown():
            try:
                if not client.wait_for_server(rospy.Duration(1.0)):
                    continue
                client.send_goal(MoveBaseGoal())
                done = client.wait_for_result(rospy.Duration(2.0))
                bump('act_ok' if done and client.get_state() == GoalStatus.SUCCEEDED else 'act_err')
            except rospy.exceptions.ROSTimeMovedBackwardsException:
                bump('time_back')
            time.sleep(0.2)

    for target in (call_across, act_across):
        threading.Thread(target=target, daemon=True).start()
    ticks = 0
    while not rospy.is_shutdown():
        pub.publish(String(data=side))
        ticks += 1
        if ticks % 5 == 0:
            with lock:
                print('counts ' + json.dumps(counts), flush=True)
        try:
            rospy.sleep(0.1)
        except rospy.exceptions.ROSTimeMovedBackwardsException:
            bump('time_back')
        except rospy.ROSInterruptException:
            break


if __name__ == '__main__':
    peer_main(sys.argv[1], sys.argv[2])
    sys.exit(0)


# -- the test -------------------------------------------------------------------------------------------------------
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason='needs root (network namespaces and TUN devices)')
SETTINGS = dict(allow_topics=ALLOW, allow_services=ALLOW)


def counts(proc) -> dict:
    with open(proc.log_path, errors='replace') as f:
        found = [line for line in f if line.startswith('counts ')]
    return json.loads(found[-1][len('counts '):]) if found else {}


def health(nodes) -> list:
    """What is wrong with the nodes across (empty: nothing): one exited, or the cloud's time went backwards."""
    wrong = [f'{os.path.basename(p.log_path)} exited with {p.returncode}' for p in nodes if not p.alive()]
    cloud = counts(nodes[1]) if len(nodes) > 1 else {}
    if cloud.get('clock_back') or cloud.get('time_back'):
        wrong.append(f"the cloud's /clock stepped back {cloud['clock_back']} times (a stale message after a fresh "
                     f"one), ROSTimeMovedBackwardsException {cloud['time_back']} times")
    return wrong


def served_again(procs, before, keys=('rx', 'call_ok', 'act_ok')) -> bool:
    now = [counts(p) for p in procs]
    return all(c.get(k, 0) > b.get(k, 0) for c, b in zip(now, before) for k in keys)


def newest_served(robot, cloud) -> list:
    """What is wrong with SHARED: both masters must have it served by the cloud's provider (the newer one)."""
    wrong = []
    for side in (robot, cloud):
        try:
            served = side.call('lookupService', SHARED)
        except RuntimeError as exc:       # no provider: between a proxy's removal and the local one's return
            wrong.append(f'{side.side} master: {exc}')
            continue
        if not served.startswith(f'rosrpc://{cloud.address}:'):
            wrong.append(f"{side.side} master: {SHARED} served by {served}, not by the cloud's newer provider")
    return wrong


@pytest.fixture(scope='module')
def flapping(tmp_path_factory, workspace):
    from bridge_testbed import two_hosts
    from cnr_harness import wait_until
    from cnr_testbed.netns import inside
    from multimaster_bridge.watch import RestoreWatch
    with two_hosts(workspace, NAME, str(tmp_path_factory.mktemp('flap')), cloud_sim_time=True) as hosts:
        robot, cloud = hosts.robot, hosts.cloud   # the cloud runs on the robot's /clock
        bridges = hosts.start_bridges(**SETTINGS)
        me = os.path.abspath(__file__)
        nodes = [robot.run([sys.executable, me, 'robot', 'cloud'], 'node_robot')]
        # the robot's SHARED reaches the cloud master before the cloud's own provider starts: the cloud's is newer
        wait_until(lambda: SHARED in {s for s, _ in cloud.call('getSystemState')[2]}, 30,
                   "the robot's shared service on the cloud master", nodes[0])
        nodes.append(cloud.run([sys.executable, me, 'cloud', 'robot'], 'node_cloud'))
        watch = RestoreWatch(robot.master_uri, cloud.master_uri, hosts.bridge_config('robot', **SETTINGS),
                             hosts.bridge_config('cloud', **SETTINGS), robot_netns=robot.namespace,
                             cloud_netns=cloud.namespace, enter=inside, interval=0.02).start()
        try:
            wait_until(lambda: watch.holds() and not newest_served(robot, cloud) and served_again(nodes, [{}, {}]),
                       60, 'the registrations across and both nodes served across before the first outage')
            yield hosts, bridges, nodes, watch
        finally:
            watch.stop()


def test_the_restore_watch_sees_a_missing_and_an_extra_registration():
    """The invariant, without a master: what one side holds of the other's nodes against what that side holds."""
    from multimaster_bridge.core.invariant import Filters, MasterView, Side, violations
    from multimaster_bridge.core.sync import Filter
    cross = Filters(Filter(['/flap/*']), Filter(['/flap/*']))
    robot = MasterView.from_system_state(([['/flap/robot/says', ['/n']], ['/rosout', ['/n']]], [], []))
    cloud = MasterView.from_system_state(([['/flap/robot/says', ['/robot/n']]], [['/flap/robot/says', ['/m']]], []))
    assert violations(Side('robot', robot, cross), Side('cloud', cloud, cross)) == \
        ['robot master: missing [sub /flap/robot/says /m], extra []']
    robot.entries.add(type(next(iter(robot.entries)))('sub', '/flap/robot/says', '/cloud/m'))
    robot.uris.update({'/cloud/m': 'http://h:1/'})
    cloud.uris.update({'/m': 'http://h:1'})
    assert violations(Side('robot', robot, cross), Side('cloud', cloud, cross)) == []
    cloud.uris['/m'] = 'http://h:2'
    assert violations(Side('robot', robot, cross), Side('cloud', cloud, cross)) == \
        ['robot master: /cloud/m at http://h:1/, the node is at http://h:2']


@needs_root
def test_every_outage_is_followed_by_a_full_restore_and_connections_come_back(flapping):
    from cnr_harness import wait_until
    from cnr_testbed.core.flap import FlapSettings, onset, schedule
    hosts, bridges, nodes, watch = flapping
    tb, robot, cloud = hosts.tb, hosts.robot, hosts.cloud
    events = schedule(SEED, COUNT, FlapSettings() if WIDE else FlapSettings(outage=(0.3, 8.0), gap=(0.5, 8.0)))
    t0 = time.monotonic()
    shift = 0.0                       # a check that took longer than the gap delays the rest of the schedule
    checked = []
    for i, event in enumerate(events):
        time.sleep(max(0.0, t0 + shift + event.start - time.monotonic()))
        watch.outage_began()
        tb.set(event.direction, **onset(event))
        time.sleep(max(0.0, t0 + shift + event.end - time.monotonic()))
        tb.set(event.direction, outage=False, loss=0.0)
        back = time.monotonic()
        watch.outage_ended(back)
        print(f'{event.describe()}: link back at {time.time():.3f} (wall clock, as in the bridges\' logs)')
        gap = events[i + 1].start - event.end if i + 1 < len(events) else 30.0
        if gap < SETTLE:
            continue
        checked.append(i)
        try:
            wait_until(lambda: watch.restored_since(back) is not None and not newest_served(robot, cloud), 5.0,
                       'the registrations across', interval=0.02)
        except Exception:
            pytest.fail(f'after outage {i + 1} ({event.describe()}): '
                        + '; '.join(watch.problems() + newest_served(robot, cloud)))
        assert not health(nodes), f'after outage {i + 1} ({event.describe()}): ' + '; '.join(health(nodes))
        shift += max(0.0, time.monotonic() - back - gap)
    before = [counts(p) for p in nodes]
    back = time.monotonic()
    wait_until(lambda: served_again(nodes, before), 20, 'the subscribers, persistent service clients and action '
               'clients on both sides to be served across again')
    served = time.monotonic() - back
    results = watch.results()
    restores = [results.restores[i] for i in checked]
    for i, event in enumerate(events):
        r = results.restores[i]
        print(f'{event.describe()}: ' + (f'restored {r:.3f} s after the link returned' if r is not None else
                                         'next outage before a restore'))
    print(f'seed {SEED}: {len(events)} outages, {len(restores)} checked: restore median {statistics.median(restores):.3f} s, '
          f'max {max(restores):.3f} s; all served again {served:.2f} s after the last check')
    assert not health(nodes), '; '.join(health(nodes))
    assert statistics.median(restores) <= RESTORE_LIMIT and max(restores) <= RESTORE_LIMIT_ANY, \
        f'restores took {sorted(restores)} s'
