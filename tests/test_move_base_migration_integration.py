"""move_base migrated while it drives the robot to a goal, on one real master with the simulator: the client's
goal continues under the same goal id in the new instance and ends SUCCEEDED, never LOST, ABORTED or PREEMPTED;
a standby has no action server and publishes nothing; a frozen instance stops commanding at once and sends no
terminal status; a cut-off instance pauses and resumes; the simulator obeys only the lease holder.

The test plays the migration manager (tests/migration_driver.py: one grantor for both hosts). On one master two
nodes cannot share the name ``/move_base``, so the instance of host ``robot`` is frozen and stopped before the
one of host ``cloud`` starts: the measured gap includes that start-up, which a real cold migration (the standby
starts before the freeze, on the other master) or a hot standby does not have; the hand-over proper is printed
too (promotion -> first velocity command of the new instance).
"""
import math
import sys
import threading
import time

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

START_X = 0.5                 # robot.launch's start pose (0.5, 0, 0)
RTF = '2.0'
IN_FLIGHT = 0.5               # [s wall] a message published before a freeze may still be on its way


# a publisher of velocity commands marked as a managed instance (argv[1]): 2 s of sim time at 10 Hz, turning
FAKE_INSTANCE = """
import sys, time, rospy
from geometry_msgs.msg import Twist
rospy.init_node('fake_instance', anonymous=True)
pub = rospy.Publisher('/mobile_base/commands/velocity', Twist, queue_size=10, headers={'cnr_instance': sys.argv[1]})
deadline = time.monotonic() + 30
while pub.get_num_connections() < 2:          # the simulator and the test's recorder
    assert time.monotonic() < deadline, 'no subscribers'
    time.sleep(0.05)
rate, cmd = rospy.Rate(10), Twist()
cmd.angular.z = 0.8
for _ in range(20):
    pub.publish(cmd)
    rate.sleep()
"""


class Recorder:
    """What the test sees on the wire: velocity commands (with their publisher's instance), status arrays,
    the robot's true pose, and an action client's transitions and feedback."""

    def __init__(self) -> None:
        from actionlib_msgs.msg import GoalStatusArray
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        self.lock = threading.Lock()
        self.cmds = []            # (wall, instance or None, v, w)
        self.statuses = []        # (wall, {goal id: status})
        self.pose = None          # (x, y, yaw, v, w)
        self.subs = [rospy.Subscriber('mobile_base/commands/velocity', Twist, self._on_cmd, queue_size=100),
                     rospy.Subscriber('move_base/status', GoalStatusArray, self._on_status, queue_size=100),
                     rospy.Subscriber('base_pose_ground_truth', Odometry, self._on_pose, queue_size=1)]

    def _on_cmd(self, msg) -> None:
        with self.lock:
            self.cmds.append((time.monotonic(), msg._connection_header.get('cnr_instance'), msg.linear.x,
                              msg.angular.z))

    def _on_status(self, msg) -> None:
        with self.lock:
            self.statuses.append((time.monotonic(), {s.goal_id.id: s.status for s in msg.status_list}))

    def _on_pose(self, msg) -> None:
        q = msg.pose.pose.orientation
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, 2.0 * math.atan2(q.z, q.w),
                     msg.twist.twist.linear.x, msg.twist.twist.angular.z)

    def cmds_from(self, instance, after=0.0, before=math.inf):
        with self.lock:
            return [c for c in self.cmds if c[1] == instance and after <= c[0] < before]

    def statuses_between(self, after, before=math.inf):
        with self.lock:
            return [s for s in self.statuses if after <= s[0] < before]

    def stopped(self) -> bool:
        return self.pose is not None and abs(self.pose[3]) < 1e-3 and abs(self.pose[4]) < 1e-3

    def close(self) -> None:
        for s in self.subs:
            s.unregister()


class Client:
    """actionlib's SimpleActionClient (as mfg uses it), recording every transition of its goal."""

    def __init__(self) -> None:
        import actionlib
        from move_base_msgs.msg import MoveBaseAction
        self.client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        self.transitions = []     # (wall, comm state, goal status)
        self.feedback = []        # wall times
        handle_transition, handle_feedback = self.client._handle_transition, self.client._handle_feedback

        def on_transition(gh):
            self.transitions.append((time.monotonic(), gh.get_comm_state(), gh.get_goal_status()))
            handle_transition(gh)

        def on_feedback(gh, feedback):
            self.feedback.append(time.monotonic())
            handle_feedback(gh, feedback)
        self.client._handle_transition, self.client._handle_feedback = on_transition, on_feedback

    def send(self, x, y, yaw=0.0):
        from move_base_msgs.msg import MoveBaseGoal
        g = MoveBaseGoal()
        g.target_pose.header.frame_id = 'map'
        g.target_pose.header.stamp = rospy.Time.now()
        g.target_pose.pose.position.x, g.target_pose.pose.position.y = x, y
        g.target_pose.pose.orientation.z, g.target_pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        self.client.send_goal(g)
        return self.client.gh.comm_state_machine.action_goal.goal_id.id

    def bad_statuses(self):
        from actionlib_msgs.msg import GoalStatus
        bad = {GoalStatus.LOST, GoalStatus.ABORTED, GoalStatus.PREEMPTED, GoalStatus.RECALLED, GoalStatus.REJECTED}
        return [t for t in self.transitions if t[2] in bad]


@pytest.fixture(scope='module')
def world(ros):
    """The simulator and map_server (no move_base), the recorder, one grantor for move_base on both hosts."""
    from migration_driver import LeaseDriver
    sim = ros.master.roslaunch('cnr_bringup', 'robot.launch', 'navigation:=false', f'real_time_factor:={RTF}')
    rec = Recorder()
    driver = LeaseDriver('move_base', hosts=('robot', 'cloud'))

    def up():
        assert sim.alive(), sim.output()[-3000:]
        return rec.pose is not None
    wait_until(up, 60, 'the simulator')
    yield sim, rec, driver
    driver.close()
    rec.close()
    ros.master.stop_child(sim)
    try:                    # the instances' parameters (migration/role: standby) would make a later move_base a standby
        ros.master.call('deleteParam', '/move_base')
    except RuntimeError:    # none set
        pass


@pytest.fixture
def instances(ros):
    """Starts move_base instances (managed standbys); stops whatever is left at the end."""
    started = []

    def start(host):
        proc = ros.master.roslaunch('cnr_navigation', 'move_base.launch', '--screen', 'migration_role:=standby',
                                    f'migration_host:={host}')
        started.append(proc)
        return proc
    yield start
    for proc in started:
        ros.master.stop_child(proc)


def action_server_up() -> bool:
    """Is move_base's action status topic advertised (an action server exists, prepared or started)?"""
    import rosgraph
    pubs = dict(rosgraph.Master('/pytest').getSystemState()[0])
    return bool(pubs.get('/move_base/status'))


def services():
    """move_base's services (not the introspection services every rospy node has, nor tf2's of its buffer)."""
    import rosgraph
    return {name for name, _ in rosgraph.Master('/pytest').getSystemState()[2]
            if name.startswith('/move_base/') and not name.endswith(('/get_loggers', '/set_logger_level',
                                                                     '/tf2_frames'))}


def sim_time_passes(seconds: float, timeout: float = 30.0) -> None:
    """An observation window of ``seconds`` of sim time (for checks that something does NOT happen)."""
    end = rospy.get_time() + seconds
    wait_until(lambda: rospy.get_time() >= end, timeout, f'{seconds} s of sim time')


def assert_clean(proc, name):
    """No traceback, no abort at shutdown and no complaint of actionlib's server in an instance's output."""
    out = proc.output()
    for bad in ('Traceback', 'Aborting on the goal', 'did not set the goal to a terminal status',
                'Should never reach this code', 'could not be taken over'):
        assert bad not in out, f'{name}: {bad!r} in its output:\n{out[-4000:]}'


def driving(instances, rec, driver, host='robot'):
    """An instance of ``host`` started, promoted and driving a client's goal: (its process, the client, the
    goal id, the goal's x)."""
    proc = instances(host)
    driver.wait_standby(90, host=host)
    client = Client()
    driver.promote(host=host)
    driver.wait_active(10, host=host)
    wait_until(lambda: client.client.wait_for_server(rospy.Duration(0.5)), 30, 'the action server')
    x0 = rec.pose[0]
    goal_x = 1.0 if x0 > 3.0 else 5.0
    goal_id = client.send(goal_x, 0.0)
    wait_until(lambda: abs(rec.pose[0] - x0) > 0.8, 120, 'the robot under way', proc)
    return proc, client, goal_id, goal_x


def test_a_goal_continues_through_a_migration_and_only_the_holder_drives(ros, world, instances):
    from actionlib_msgs.msg import GoalStatus
    from migration_manager.core import state as codec
    sim, rec, driver = world
    goal_x, goal_y = 5.0, 0.0

    # ---- A (host robot) as a standby: inputs only; no action server, no services, no commands
    a = instances('robot')
    driver.wait_standby(90, host='robot')
    client = Client()
    from geometry_msgs.msg import PoseStamped
    simple = rospy.Publisher('move_base_simple/goal', PoseStamped, queue_size=1, latch=True)
    target = PoseStamped()
    target.header.frame_id = 'map'
    target.pose.position.x, target.pose.orientation.w = 3.0, 1.0
    simple.publish(target)                                  # a standby must not act on it
    t0 = time.monotonic()
    sim_time_passes(3.0)
    # its action server is prepared (advertised, connected) but silent: no status, so no client sees a server
    assert action_server_up() and not services(), services()
    assert not client.client.wait_for_server(rospy.Duration(0.5))
    assert not rec.cmds_from('move_base@robot', t0) and rec.stopped()
    simple.unregister()

    # ---- promoted: the action server and the services appear
    driver.promote(host='robot')
    driver.wait_active(10, host='robot')
    wait_until(lambda: client.client.wait_for_server(rospy.Duration(0.5)), 30, 'the action server of A')
    wait_until(lambda: {'/move_base/make_plan', '/move_base/clear_costmaps', '/move_base/set_parameters'} <=
               services(), 10, 'the services of A')
    goal_id = client.send(goal_x, goal_y)

    # ---- mid-way: freeze A; it stops commanding at once, without a terminal status
    wait_until(lambda: rec.pose[0] > START_X + 0.45 * (goal_x - START_X), 120, 'the robot half-way', a)
    assert rec.cmds_from('move_base@robot'), 'A never commanded'
    assert client.client.get_state() == GoalStatus.ACTIVE
    state = driver.freeze(host='robot')
    t_frozen = time.monotonic()
    g = state['goal']
    assert g['id'] == goal_id and g['frame'] == 'map' and state['next_goal'] is None, state
    assert (g['x'], g['y']) == pytest.approx((goal_x, goal_y), abs=1e-6)
    wait_until(rec.stopped, 20, 'the robot to stop (the base watchdog: nobody commands)')
    assert not rec.cmds_from('move_base@robot', t_frozen + IN_FLIGHT), 'A commanded after its freeze'
    last_a = rec.cmds_from('move_base@robot')[-1][0]
    assert client.client.get_state() == GoalStatus.ACTIVE

    # ---- A stopped (its process ends without aborting the goal); B (host cloud) starts as a standby
    a.stop()
    assert_clean(a, 'A')
    t_b_start = time.monotonic()
    b = instances('cloud')
    driver.wait_standby(90, host='cloud')
    t_b_standby = time.monotonic()
    assert not services()
    assert not [s for s in rec.statuses_between(t_frozen + IN_FLIGHT)], 'status after the freeze, before B'
    assert client.client.get_state() == GoalStatus.ACTIVE and not client.bad_statuses()

    # a state that does not fit is refused, naming the field (and B stays a standby)
    bad = dict(state, goal=dict(g, id=7))
    res = driver.controls['cloud'](command='promote', term=1000, state=codec.encode('move_base', bad))
    assert not res.ok and 'goal.id' in res.message, res
    driver.wait_role('standby', 5, host='cloud')

    # ---- B promoted with A's state: it takes the goal over (same id) and drives to the goal
    t_promote = time.monotonic()
    driver.promote(state, host='cloud')
    driver.wait_active(10, host='cloud')
    wait_until(lambda: rec.cmds_from('move_base@cloud'), 60, 'the first command of B', b)
    first_b = rec.cmds_from('move_base@cloud')[0][0]
    wait_until(lambda: client.client.wait_for_result(rospy.Duration(0.2)), 180, 'the goal result', b)
    t_result = time.monotonic()
    assert client.client.get_state() == GoalStatus.SUCCEEDED, client.client.get_goal_status_text()
    assert not client.bad_statuses(), client.transitions
    x, y = rec.pose[:2]
    assert math.hypot(x - goal_x, y - goal_y) <= 0.2, (x, y)
    assert [t for t in client.feedback if t > t_promote], 'no feedback from B'
    # every status array from B has the goal, ACTIVE from the very first one, then SUCCEEDED
    from_b = rec.statuses_between(t_promote, t_result)
    assert from_b and from_b[0][1].get(goal_id) == GoalStatus.ACTIVE, from_b[:3]
    assert all(s[1].get(goal_id) in (GoalStatus.ACTIVE, GoalStatus.SUCCEEDED) for s in from_b), from_b
    print(f'\nmove_base migration on one master: last command of A -> first command of B '
          f'{first_b - last_a:.2f} s wall (freeze -> A stopped {t_b_start - t_frozen:.2f} s, '
          f'B start-up to standby {t_b_standby - t_b_start:.2f} s); hand-over proper: promotion of B -> '
          f'its first command {first_b - t_promote:.2f} s; goal {goal_id} SUCCEEDED '
          f'{math.hypot(x - goal_x, y - goal_y):.3f} m from the target')

    # ---- the fence: the frozen instance's commands are ignored by the simulator, the holder's obeyed
    def turn_with(instance):
        yaw0 = rec.pose[2]
        proc = ros.master.run([sys.executable, '-c', FAKE_INSTANCE, instance], 'fake_instance')
        wait_until(lambda: proc.poll() is not None, 60, f'the commands of {instance}')
        assert proc.returncode == 0, proc.output()
        wait_until(rec.stopped, 20, 'the robot to stop')
        return abs(math.remainder(rec.pose[2] - yaw0, 2 * math.pi))
    assert turn_with('move_base@robot') < 0.02                 # A's id: dropped
    assert turn_with('move_base@cloud') > 0.3                  # the holder's id: obeyed
    assert b.alive()
    assert_clean(b, 'B')


def test_a_cut_off_instance_pauses_and_resumes_and_a_frozen_one_takes_its_goal_back(world, instances):
    """Lapse: no commands while the lease is not renewed, the goal resumes when it is. Rollback: a frozen
    instance promoted again with its own state (a migration whose target failed) continues the goal."""
    from actionlib_msgs.msg import GoalStatus
    sim, rec, driver = world
    c, client, goal_id, goal_x = driving(instances, rec, driver)

    # ---- lapse
    driver.cut_off()                                            # renewals unanswered: the lease runs out
    driver.wait_role('promoted', 5, host='robot')
    t_lapse = time.monotonic()
    wait_until(rec.stopped, 20, 'the robot to stop while the lease lapsed')
    x_paused = rec.pose[0]
    sim_time_passes(3.5)                                       # longer than controller_patience (3 s)
    assert not rec.cmds_from('move_base@robot', t_lapse + IN_FLIGHT), 'commands during the lapse'
    assert client.client.get_state() == GoalStatus.ACTIVE
    assert abs(rec.pose[0] - x_paused) < 0.01
    with driver.lock:
        driver.answering = True                                 # the link is back
    driver.wait_active(10, host='robot')
    wait_until(lambda: abs(rec.pose[0] - x_paused) > 0.8, 120, 'the robot under way again', c)

    # ---- frozen, then promoted again with its own state (rolled back)
    state = driver.freeze(host='robot')
    t_frozen = time.monotonic()
    assert state['goal']['id'] == goal_id
    wait_until(rec.stopped, 20, 'the robot to stop after the freeze')
    assert not rec.cmds_from('move_base@robot', t_frozen + IN_FLIGHT), 'commands after the freeze'
    assert not rec.statuses_between(t_frozen + IN_FLIGHT), 'status after the freeze'
    t_promote = time.monotonic()
    driver.promote(state, host='robot')
    driver.wait_active(10, host='robot')

    wait_until(lambda: client.client.wait_for_result(rospy.Duration(0.2)), 180, 'the goal result', c)
    t_result = time.monotonic()
    assert client.client.get_state() == GoalStatus.SUCCEEDED, client.client.get_goal_status_text()
    assert not client.bad_statuses(), client.transitions
    assert math.hypot(rec.pose[0] - goal_x, rec.pose[1]) <= 0.2
    again = rec.statuses_between(t_promote, t_result)
    assert again and again[0][1].get(goal_id) == GoalStatus.ACTIVE, again[:3]
    assert c.alive()
    assert_clean(c, 'C')


class TakeoverPair:
    """Two action servers on one action name, as two instances use it (over real TCPROS in this process, on the
    simulator's clock): A started, B prepared (a standby); an execute callback that records which server runs
    which goal and ends a goal when the test says so."""

    def __init__(self, ns: str) -> None:
        import actionlib
        from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
        from cnr_navigation.action_server import TakeoverActionServer
        self.ran, self.finish = [], set()
        self.servers = {name: TakeoverActionServer(ns, MoveBaseAction, self._execute(name)) for name in 'ab'}
        self.a, self.b = self.servers['a'], self.servers['b']
        self.b.prepare()
        self.a.start_with([])
        self.client = actionlib.ActionClient(ns, MoveBaseAction)
        self.goal = MoveBaseGoal()
        self.goal.target_pose.header.frame_id = 'map'
        self.goal.target_pose.pose.orientation.w = 1.0
        wait_until(lambda: self.client.wait_for_server(rospy.Duration(0.2)), 30, 'the action server')
        wait_until(lambda: self.a.action_server.goal_sub.get_num_connections() >= 1 and
                   self.b.action_server.goal_sub.get_num_connections() >= 1, 30, 'both servers connected')

    def _execute(self, name):
        def cb(_goal):
            server = self.servers[name]
            gid = server.current_goal.get_goal_id().id
            self.ran.append((name, gid))
            while not rospy.core.is_shutdown():
                if not server.started:                    # released (frozen): no terminal status
                    with server.action_server.lock, server.lock:
                        return
                if server.is_preempt_requested():
                    server.set_preempted()
                    return
                if gid in self.finish:
                    server.set_succeeded()
                    return
                time.sleep(0.02)
        return cb

    def send(self):
        h = self.client.send_goal(self.goal)
        return h, h.comm_state_machine.action_goal.goal_id.id

    def freeze_a(self):
        """A's state (the pursued goal, what it received), then its server released."""
        with self.a.action_server.lock, self.a.lock:
            seen = self.a.seen()
            active = self.a.current_goal.goal
        self.a.release()
        return active, seen

    def close(self) -> None:
        for server in self.servers.values():
            close_server(server)


def close_server(server) -> None:
    """A TakeoverActionServer made in this process released, its execute thread ended, its topics unregistered."""
    server.release()
    with server.terminate_mutex:
        server.need_to_terminate = True
    with server.execute_condition:
        server.execute_condition.notify()
    server.action_server.goal_sub.unregister()
    server.action_server.cancel_sub.unregister()
    for pub in (server.action_server.status_pub, server.action_server.result_pub, server.action_server.feedback_pub):
        pub.unregister()


@pytest.fixture
def pair(world, request):
    p = TakeoverPair('/takeover_' + request.node.name[:40])
    yield p
    p.close()


def test_a_goal_and_a_cancel_sent_while_no_instance_is_active_are_taken_up_by_the_next(pair):
    """A goal A finished, a goal A is pursuing when it is frozen, then — no instance active — a cancel of that
    goal and a new goal. B, promoted with A's state, takes the pursued goal over, replays exactly the cancel and
    the new goal (not the finished one), and the client's newest goal ends SUCCEEDED from B."""
    from actionlib_msgs.msg import GoalStatus
    a, b, ran = pair.a, pair.b, pair.ran
    h0, gid0 = pair.send()
    wait_until(lambda: ('a', gid0) in ran, 30, 'A running the first goal')
    pair.finish.add(gid0)
    wait_until(lambda: h0.get_goal_status() == GoalStatus.SUCCEEDED, 30, 'the first goal to succeed')
    h1, gid1 = pair.send()
    wait_until(lambda: ('a', gid1) in ran, 30, 'A running the second goal')
    wait_until(lambda: len(b._parked) >= 2, 30, 'B to park the goals it received as a standby')

    active, (seen_goals, seen_cancels) = pair.freeze_a()
    assert gid0 in seen_goals and gid1 in seen_goals
    # ---- the gap: a cancel of the pursued goal and a new goal reach no active instance
    h1.cancel()
    # the cancel and the goal travel on two topics (two connections): B parks them in the order they arrive, so
    # the new goal is sent once the cancel is parked (sent back to back, the goal overtook it in one CI run)
    wait_until(lambda: len(b._parked) >= 3, 30, 'B to park the cancel')
    h2, gid2 = pair.send()
    wait_until(lambda: len(b._parked) >= 4, 30, 'B to park the new goal')
    assert not [r for r in ran if r[1] == gid2]

    # ---- B promoted with A's state
    replayed = b.start_with([(active, 'active', False)], seen_goals, seen_cancels)
    assert replayed == [f'cancel {gid1}', f'goal {gid2}'], replayed
    wait_until(lambda: ('b', gid2) in ran, 30, 'B running the goal sent in the gap')
    pair.finish.add(gid2)
    wait_until(lambda: h2.get_goal_status() == GoalStatus.SUCCEEDED, 30, 'the gap goal to succeed from B')
    assert ('b', gid0) not in ran                      # the finished goal is not run again
    assert h1.get_goal_status() in (GoalStatus.PREEMPTED, GoalStatus.PREEMPTING), h1.get_goal_status()
    # B's own record carries on what A received: a next hand-over knows it too
    assert {gid0, gid1, gid2} <= set(b.seen()[0])


def test_a_goal_the_active_instance_missed_is_taken_up_with_the_cancel_it_did_receive(pair):
    """A goal that reached only the standby (lost to the active instance: seen in a campaign, a fresh cloud
    clone whose subscription to the client was still connecting), then the client's cancel-all, which A did
    receive. B, promoted, takes the goal up *and* applies that cancel to it: the goal ends cancelled and is
    never driven (it was driven, 12 s across the corridor, before this rule)."""
    from actionlib_msgs.msg import GoalStatus
    from move_base_msgs.msg import MoveBaseActionGoal
    a, b, ran = pair.a, pair.b, pair.ran
    lost = MoveBaseActionGoal()                           # as the client would send it, delivered to B only
    lost.header.stamp = rospy.Time.now()
    lost.goal_id.stamp, lost.goal_id.id = lost.header.stamp, '/client-lost-1'
    lost.goal = pair.goal
    b.action_server.internal_goal_callback(lost)
    pair.client.cancel_all_goals()
    wait_until(lambda: len(b._parked) >= 2 and a.seen()[1], 30, 'the cancel at both servers')
    _, (seen_goals, seen_cancels) = pair.freeze_a()
    assert '/client-lost-1' not in seen_goals
    replayed = b.start_with([], seen_goals, seen_cancels)
    assert replayed == ['goal /client-lost-1', 'cancel /client-lost-1'], replayed

    def status():
        return {s.status.goal_id.id: s.status.status for s in b.action_server.status_list}.get('/client-lost-1')
    # cancelled before B's execute thread could run it (RECALLED), or the moment it started (PREEMPTED)
    wait_until(lambda: status() in (GoalStatus.RECALLED, GoalStatus.PREEMPTED), 10, 'the lost goal cancelled')


def node_subscriptions(node: str) -> set:
    import rosgraph
    return {t for t, nodes in rosgraph.Master('/pytest').getSystemState()[1] if node in nodes}


def test_a_retired_instance_sleeps_without_its_inputs_and_wakes_to_take_a_goal_over(world, instances):
    """Dormant (config/migration.yaml ``dormant``): a frozen instance put to sleep drops its sensor, odometry
    and tf subscriptions and refuses a promotion; woken, it subscribes again, is a ready standby (same
    process) and, promoted with the state it was frozen with, drives the goal to SUCCEEDED."""
    from actionlib_msgs.msg import GoalStatus
    sim, rec, driver = world
    d, client, goal_id, goal_x = driving(instances, rec, driver)
    inputs = {'/odom', '/tf', '/scan'}
    assert inputs <= node_subscriptions('/move_base'), node_subscriptions('/move_base')

    # an active instance cannot sleep (only a frozen one or a standby); frozen, it can
    res = driver.controls['robot'](command='sleep')
    assert not res.ok and 'only a frozen instance or a standby' in res.message, res
    state = driver.freeze(host='robot')
    assert state['goal']['id'] == goal_id
    pid = driver.status.pid
    res = driver.controls['robot'](command='sleep')
    assert res.ok, res.message
    driver.wait_role('dormant', 10, host='robot')
    wait_until(lambda: not inputs & node_subscriptions('/move_base'), 20, 'the inputs unsubscribed', d)
    assert not driver.status.ready
    term = driver.grantor.term
    res = driver.controls['robot'](command='promote', term=term + 1)
    assert not res.ok and 'dormant' in res.message, res
    wait_until(rec.stopped, 20, 'the robot to stop')
    # ... but it keeps following the active instance's replicas: woken, it holds one at once (a re-subscription on
    # waking missed the whole state it asked for, and every migration to it waited out timeouts.replica)
    from cnr_msgs.msg import InstanceStatus, ModuleState
    from migration_manager.core import state as codec
    assert '/migration/move_base/state' in node_subscriptions('/move_base')
    replicas = rospy.Publisher('/migration/move_base/state', ModuleState, queue_size=2)
    try:
        wait_until(lambda: replicas.get_num_connections() > 0, 10, 'the dormant instance to follow the replicas', d)
        replicas.publish(ModuleState(module='move_base', instance='move_base@cloud', term=term + 1, seq=3, base_seq=0,
                                     data=codec.encode('move_base', state)))
        wait_until(lambda: driver.status.replica_of == 'move_base@cloud', 10, 'the dormant status naming it', d)
    finally:
        replicas.unregister()
    assert driver.status.role == InstanceStatus.DORMANT and driver.status.replica_seq == 3

    # woken: a standby again (the same process), ready once its local costmap is current
    res = driver.controls['robot'](command='wake')
    assert res.ok, res.message
    st = wait_until(lambda: driver.status if driver.status.role == InstanceStatus.STANDBY and driver.status.ready
                    else None,
                    30, 'the woken standby ready', d)
    assert st.pid == pid and (st.replica_of, st.replica_seq) == ('move_base@cloud', 3)
    assert inputs <= node_subscriptions('/move_base')
    driver.promote(state, host='robot')
    driver.wait_active(10, host='robot')
    wait_until(lambda: client.client.wait_for_result(rospy.Duration(0.2)), 180, 'the goal result', d)
    assert client.client.get_state() == GoalStatus.SUCCEEDED, client.client.get_goal_status_text()
    assert not client.bad_statuses(), client.transitions
    assert math.hypot(rec.pose[0] - goal_x, rec.pose[1]) <= 0.2
    assert d.alive()
    assert_clean(d, 'D')


def test_a_standby_never_promoted_sleeps_and_wakes_ready(world, instances):
    """The manager's dormant instance from the start (a module placed on the other host): a fresh standby put to
    sleep closes its inputs in the same process and, woken, is a ready standby again."""
    from cnr_msgs.msg import InstanceStatus
    sim, rec, driver = world
    proc = instances('robot')
    driver.wait_standby(90, host='robot')
    pid = driver.status.pid
    res = driver.controls['robot'](command='sleep')
    assert res.ok, res.message
    driver.wait_role('dormant', 10, host='robot')
    wait_until(lambda: not {'/odom', '/tf', '/scan'} & node_subscriptions('/move_base'), 20, 'the inputs unsubscribed',
               proc)
    res = driver.controls['robot'](command='wake')
    assert res.ok, res.message
    st = wait_until(lambda: driver.status if driver.status.role == InstanceStatus.STANDBY and driver.status.ready
                    else None, 30, 'the woken standby ready', proc)
    assert st.pid == pid and {'/odom', '/tf', '/scan'} <= node_subscriptions('/move_base')
    assert_clean(proc, 'robot')


def test_a_goal_that_arrives_while_the_execute_thread_looks_is_not_left_waiting(ros):
    """actionlib's execute thread looks for a new goal, then waits without a lock: a goal arriving in between is
    notified to nobody and starts only when that wait times out (0.1 s). Here the goal is delivered by another
    thread at exactly that moment (the look waits up to 1 s for it): it must start on a notification, with no
    wait of the execute thread timing out between its arrival and its start."""
    from actionlib_msgs.msg import GoalID
    from move_base_msgs.msg import MoveBaseAction, MoveBaseActionGoal
    from cnr_navigation.action_server import TakeoverActionServer

    ran = threading.Event()
    timed_out = []                # waits of the execute thread that ended by their timeout, once armed

    class Recording(threading.Condition):
        armed = False

        def wait(self, timeout=None):
            woken = super().wait(timeout)
            if self.armed and not woken and not ran.is_set():
                timed_out.append(timeout)
            return woken

    class Server(TakeoverActionServer):
        EXECUTE_POLL = 60.0       # this server's own look: a timeout would show as a hang, not a pass
        armed = False

        def is_new_goal_available(self):
            seen = super().is_new_goal_available()
            if self.armed and not seen:               # the goal arrives between the look and the wait
                self.armed = False
                goal = MoveBaseActionGoal()
                goal.goal_id = GoalID(id='between', stamp=rospy.Time.now())
                goal.goal.target_pose.header.frame_id = 'map'
                goal.goal.target_pose.pose.orientation.w = 1.0
                sender = threading.Thread(target=self.action_server.internal_goal_callback, args=(goal,))
                sender.start()
                sender.join(1.0)                      # done at once unless the look holds the lock
            return seen

    def execute(_goal):
        ran.set()
        server.set_succeeded()

    server = Server('/takeover_lost_wakeup', MoveBaseAction, execute)
    old, server.execute_condition = server.execute_condition, Recording(server.lock)
    with old:
        old.notify()              # the execute thread leaves its first wait and takes the recording condition
    try:
        server.start_with([])
        with server.execute_condition:       # arm the look, then wake the execute thread for it
            server.armed = server.execute_condition.armed = True
            server.execute_condition.notify()
        wait_until(ran.is_set, 20, 'the goal that arrived during the look to run')
        assert server.current_goal.get_goal_id().id == 'between'
        assert not timed_out, f'the goal waited for the execute thread\'s wait to time out ({timed_out} s)'
    finally:
        close_server(server)
