"""The bridge under a flapping link (root): two real masters in the testbed's namespaces, two real bridges, real
nodes on both sides publishing, subscribing, serving and calling across, and a short seeded schedule of outages
(cuts and loss bursts; both directions, up only, down only; :mod:`cnr_testbed.core.flap`).

After every outage the invariant holds again within a second of the link's return: each master's registrations of
the other host's nodes are exactly the other master's own registrations that the allow-lists let across (each under
``/<peer>/<node>`` at the node's own URI), and a service both hosts provide is served by the newer provider on both.
At the end a subscriber, a persistent service client and an actionlib client on each side are served across again,
with neither side restarted.

Run as a script (``tests/test_multimaster_bridge_flap.py SIDE OTHER``) this module is the test's node on one side.
"""
import fnmatch
import json
import os
import statistics
import sys
import time

import pytest

NAME = f'flp{os.getpid() % 10000}'
ALLOW = ['/flap/*', '/clock']
SHARED = '/flap/shared'             # served on both hosts: the cloud's provider is the newer one
SEED, COUNT = 18, 8                 # cuts of 0.5-6.7 s: up only, down only and both, and loss bursts; ~41 s in all
RESTORE_LIMIT = 1.0                 # s after the link returns
CHECK_GAP = 1.2                     # an outage is checked when the link stays up at least this long after it


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


# -- the rule, without a master --------------------------------------------------------------------------------------
def clock_state() -> dict:
    """A robot whose simulator publishes /clock and /odom and whose driver publishes /temperature."""
    return {'pubs': {'/clock': ['/sim'], '/odom': ['/sim'], '/temperature': ['/driver']}, 'subs': {}, 'srvs': {},
            'types': {'/clock': 'rosgraph_msgs/Clock', '/odom': 'nav_msgs/Odometry',
                      '/temperature': 'sensor_msgs/Temperature'}, 'md5': {},
            'nodes': {'/sim': 'http://10.77.0.1:4001/', '/driver': 'http://10.77.0.1:4002/'}}


def test_a_publisher_of_an_in_order_topic_keeps_its_uri_spelling_in_every_generation():
    """A forced reconnect (another spelling) gives a subscriber a second connection while the first still holds
    the outage's backlog: /clock would step back when TCP delivers it. The simulator keeps its spelling for all its
    topics (a node has one URI in a master); the driver is reconnected as before."""
    from multimaster_bridge.core import sync
    every = sync.Filter(['*'])
    apis = []
    for generation in range(4):
        result = sync.plan('robot', clock_state(), sync.Snapshot(), set(), every, every, {}, {}, generation,
                           sync.Filter(['/clock']))
        apis.append({r.caller_id: r.caller_api for r in result.registrations})
    assert [a['/robot/sim'] for a in apis] == ['http://10.77.0.1:4001/'] * 4
    assert [a['/robot/driver'] for a in apis] == ['http://10.77.0.1:4002/', 'http://10.77.0.1:4002'] * 2
    assert sync.in_order_publishers(clock_state(), sync.Filter(['/clock'])) == {'/sim'}
    # without in-order topics every node alternates, the simulator too
    plain = sync.plan('robot', clock_state(), sync.Snapshot(), set(), every, every, {}, {}, 1, sync.Filter())
    assert {r.caller_api for r in plain.registrations if r.caller_id == '/robot/sim'} == {'http://10.77.0.1:4001'}


def test_a_peer_that_lost_us_alone_has_its_nodes_reconnected_here_once():
    """An outage in one direction: only the peer lost us, but our connections to its nodes stalled as well."""
    from multimaster_bridge.core.sync import rejoined_without_our_loss as rejoined
    assert rejoined(False, True, since_our_return=30.0, loss_timeout=1.5)          # it lost us, we heard it
    assert not rejoined(True, True, 30.0, 1.5) and not rejoined(False, False, 30.0, 1.5)
    assert not rejoined(None, True, 30.0, 1.5)                                      # its first heartbeat
    # both lost each other: our own loss already gave a new generation; a second one would undo it
    assert not rejoined(False, True, since_our_return=0.2, loss_timeout=1.5)


def test_in_order_topics_is_a_required_list_of_globs():
    from cnr_params import ConfigError, Section, load_yaml
    from multimaster_bridge.core import config
    here = os.path.dirname(os.path.abspath(__file__))
    base = load_yaml(os.path.join(here, '..', 'config', 'bridge.yaml'))
    base.update(name='robot', listen='10.77.0.1:11511', peers=[dict(name='cloud', address='10.77.0.2:11511')],
                secret='0123456789')
    assert config.parse(Section(base, '/bridge')).in_order.passes('/clock')
    for value, message in ((None, 'in_order_topics: missing'), ([3], 'in_order_topics')):
        data = dict(base, in_order_topics=value) if value is not None else \
            {k: v for k, v in base.items() if k != 'in_order_topics'}
        with pytest.raises(ConfigError, match=message):
            config.parse(Section(data, '/bridge'))


# -- the test -------------------------------------------------------------------------------------------------------
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason='needs root (network namespaces and TUN devices)')


def allowed(name: str) -> bool:
    return any(fnmatch.fnmatchcase(name, g) for g in ALLOW)


def own_registrations(side, peer_name: str) -> set:
    """``side``'s own (not proxied) registrations that the allow-lists let across: (kind, name, node)."""
    pubs, subs, srvs = side.call('getSystemState')
    out = set()
    for kind, table in (('pub', pubs), ('sub', subs), ('srv', srvs)):
        out |= {(kind, name, n) for name, nodes in table if allowed(name) and name != SHARED
                for n in nodes if not n.startswith(f'/{peer_name}/')}
    return out


def proxies(side, peer_name: str) -> set:
    """The registrations of ``peer_name``'s nodes on ``side``'s master, as the peer's own names."""
    pubs, subs, srvs = side.call('getSystemState')
    prefix = f'/{peer_name}'
    return {(kind, name, n[len(prefix):]) for kind, table in (('pub', pubs), ('sub', subs), ('srv', srvs))
            for name, nodes in table if name != SHARED for n in nodes if n.startswith(prefix + '/')}


def invariant(robot, cloud) -> list:
    """What is wrong with the registrations across (empty: nothing)."""
    wrong = []
    for side, peer in ((robot, cloud), (cloud, robot)):
        want, have = own_registrations(peer, side.side), proxies(side, peer.side)
        if want != have:
            wrong.append(f'{side.side} master: missing {sorted(want - have)}, extra {sorted(have - want)}')
            continue
        for node in sorted({n for _, _, n in have}):
            there, here = peer.call('lookupNode', node), side.call('lookupNode', f'/{peer.side}{node}')
            if there.rstrip('/') != here.rstrip('/'):
                wrong.append(f'{side.side} master: /{peer.side}{node} at {here}, the node is at {there}')
    newest = cloud.call('lookupService', SHARED)
    for side in (robot, cloud):
        served = side.call('lookupService', SHARED)
        if served != newest:
            wrong.append(f'{side.side} master: {SHARED} served by {served}, not by the newer provider {newest}')
    return wrong


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


@pytest.fixture(scope='module')
def flapping(tmp_path_factory, workspace):
    from cnr_testbed.api import Testbed
    from cnr_testbed.rosside import RosSide, start_bridge
    from cnr_harness import wait_until
    tb = Testbed(os.path.join(workspace, 'config', 'testbed.yaml'),
                 {'name': NAME, 'robot.namespace': f'{NAME}-robot', 'cloud.namespace': f'{NAME}-cloud'})
    tb.up()
    logs = tmp_path_factory.mktemp('flap')
    robot = RosSide(tb, 'robot', log_dir=str(logs))
    cloud = RosSide(tb, 'cloud', log_dir=str(logs))
    try:
        robot.start_master()
        cloud.start_master(use_sim_time=True)      # the cloud runs on the robot's /clock
        secret = logs / 'secret'
        secret.write_text('flap-test-secret\n')
        settings = dict(allow_topics=ALLOW, allow_services=ALLOW)
        bridges = [start_bridge(robot, cloud, str(secret), **settings),
                   start_bridge(cloud, robot, str(secret), **settings)]
        wait_until(lambda: 'peer cloud is up' in bridges[0].output() and 'peer robot is up' in bridges[1].output(),
                   30, 'the bridges to see each other')
        me = os.path.abspath(__file__)
        nodes = [robot.run([sys.executable, me, 'robot', 'cloud'], 'node_robot')]
        # the robot's SHARED reaches the cloud master before the cloud's own provider starts: the cloud's is newer
        wait_until(lambda: SHARED in {s for s, _ in cloud.call('getSystemState')[2]}, 30,
                   "the robot's shared service on the cloud master", nodes[0])
        nodes.append(cloud.run([sys.executable, me, 'cloud', 'robot'], 'node_cloud'))
        wait_until(lambda: not invariant(robot, cloud) and served_again(nodes, [{}, {}]), 60,
                   'the registrations across and both nodes served across before the first outage')
        yield tb, robot, cloud, bridges, nodes
    finally:
        cloud.stop()
        robot.stop()
        tb.down()


@needs_root
def test_every_outage_is_followed_by_a_full_restore_and_connections_come_back(flapping):
    from cnr_harness import wait_until
    from cnr_testbed.core.flap import FlapSettings, onset, schedule
    tb, robot, cloud, bridges, nodes = flapping
    events = schedule(SEED, COUNT, FlapSettings(outage=(0.3, 8.0), gap=(0.5, 8.0)))
    restores, lost = [], 0
    t0 = time.monotonic()
    shift = 0.0                       # a check that took longer than the gap delays the rest of the schedule
    for i, event in enumerate(events):
        time.sleep(max(0.0, t0 + shift + event.start - time.monotonic()))
        tb.set(event.direction, **onset(event))
        time.sleep(max(0.0, t0 + shift + event.end - time.monotonic()))
        tb.set(event.direction, outage=False, loss=0.0)
        back = time.monotonic()
        gap = events[i + 1].start - event.end if i + 1 < len(events) else 30.0
        if gap < CHECK_GAP:
            print(f'{event.describe()}: next outage after {gap:.2f} s, not checked')
            continue
        try:
            wait_until(lambda: not invariant(robot, cloud), 5.0, 'the registrations across', interval=0.02)
        except Exception:
            pytest.fail(f'after outage {i + 1} ({event.describe()}): ' + '; '.join(invariant(robot, cloud)))
        restored = time.monotonic() - back
        assert not health(nodes), f'after outage {i + 1} ({event.describe()}): ' + '; '.join(health(nodes))
        restores.append(restored)
        lost += event.duration > 1.5 and event.kind == 'outage'
        shift += max(0.0, time.monotonic() - back - gap)
        print(f'{event.describe()}: restored {restored:.3f} s after the link returned')
    before = [counts(p) for p in nodes]
    back = time.monotonic()
    wait_until(lambda: served_again(nodes, before), 20, 'the subscribers, persistent service clients and action '
               'clients on both sides to be served across again')
    print(f'{len(events)} outages, {len(restores)} checked ({lost} cuts longer than the loss timeout): restore '
          f'median {statistics.median(restores):.3f} s, max {max(restores):.3f} s; all served again '
          f'{time.monotonic() - back:.2f} s after the last check')
    assert not health(nodes), '; '.join(health(nodes))
    assert max(restores) <= RESTORE_LIMIT, f'restores took {sorted(restores)} s'
