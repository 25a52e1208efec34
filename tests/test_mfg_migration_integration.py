"""mfg as a managed instance in the corridor mission on one real master (everything but mfg from mission.launch,
mfg started by the test with its ~migration parameters), driven through the real lease protocol by the test
(tests/migration_driver.py) — three instances one after the other, as cold migrations would run them:

1. instance A as a standby follows its inputs (warm) but sends no goal and publishes nothing; promoted, it
   patrols, meets the heaters' abnormal values and searches; frozen while checking a direction, its state holds
   the search and that goal, and move_base finishes the goal (nothing cancelled, nothing more sent);
2. instance B, promoted with A's state, drives to the same target and completes A's search (the heaters' cell),
   then patrols; frozen mid-goal, promoted again with its own state (a rolled-back migration: a frozen instance
   resumes), frozen again;
3. instance C, promoted with B's state, re-sends the same patrol goal and the patrol goes on; cut off from the
   lease, it lets move_base finish the goal and sends nothing until renewals are answered again.
"""
import math
import os
import threading

import pytest
import yaml

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

HEATER_CELL = 19            # col 8, row 1 in config/scenarios/corridor.yaml
GOAL_TIMEOUT = 60.0         # s of sim time (config/mfg.yaml: 120): a corridor goal takes < 40 s; B is promoted only
                            # after A's check goal has used up this time (a hand-over longer than the goal's time)


@pytest.fixture(scope='module')
def mission(ros, workspace, tmp_path_factory):
    report = tmp_path_factory.mktemp('report')
    proc = ros.master.run(['rosrun', 'cnr_bringup', 'cnr_launch', 'cnr_mission', 'mission.launch',
                           'monitor_required:=false', 'mfg:=false', 'scenario:=corridor',
                           f'map:={workspace}/maps/corridor.yaml', 'real_time_factor:=4',
                           f'report_dir:={report}', f'store:={report}/store.tsv'], log_name='mfg_migration_mission')
    yield proc
    proc.stop()


@pytest.fixture
def mfg_params(ros, workspace):
    """/mfg's parameters as modules.launch loads them: config/mfg.yaml, the scenario's mfg section, ~migration."""
    from cnr_params import load_yaml
    from migration_driver import managed_params
    mfg = dict(load_yaml(os.path.join(workspace, 'config', 'mfg.yaml'))['mfg'])
    mfg.update(load_yaml(os.path.join(workspace, 'config', 'scenarios', 'corridor.yaml'))['mfg'])
    mfg['goal_timeout'] = GOAL_TIMEOUT
    ros.master.call('setParam', '/mfg', {'mfg': mfg, 'migration': managed_params(workspace, 'robot')})
    yield
    ros.master.call('deleteParam', '/mfg')


class Recorder:
    """Everything mfg sends or that shows it: move_base goals and cancels, move_base results, ~state, hotspot,
    ~activity; each with the sim time it was received at (and the message's own stamp)."""

    def __init__(self):
        from actionlib_msgs.msg import GoalID
        from cnr_msgs.msg import Hotspot, MfgActivity, SearchState
        from move_base_msgs.msg import MoveBaseActionGoal, MoveBaseActionResult
        from nav_msgs.msg import Odometry
        self.lock = threading.Lock()
        self.log = {k: [] for k in ('goal', 'cancel', 'result', 'state', 'hotspot', 'activity')}
        self.pose = None
        self.subs = [rospy.Subscriber('/move_base/goal', MoveBaseActionGoal, self._add('goal'), queue_size=50),
                     rospy.Subscriber('/move_base/cancel', GoalID, self._add('cancel'), queue_size=50),
                     rospy.Subscriber('/move_base/result', MoveBaseActionResult, self._add('result'), queue_size=50),
                     rospy.Subscriber('/mfg/state', SearchState, self._add('state'), queue_size=100),
                     rospy.Subscriber('/hotspot', Hotspot, self._add('hotspot'), queue_size=10),
                     rospy.Subscriber('/mfg/activity', MfgActivity, self._add('activity'), queue_size=10),
                     rospy.Subscriber('/base_pose_ground_truth', Odometry,
                                      lambda m: setattr(self, 'pose', m.pose.pose.position), queue_size=1)]

    def _add(self, kind):
        def callback(msg):
            with self.lock:
                self.log[kind].append((rospy.Time.now().to_sec(), msg))
        return callback

    def connected(self, ros) -> bool:
        """Is every subscription connected to every publisher the master lists for its topic? A new instance's
        output is only seen once the recorder has connected to it, and rospy retries a slow publisher with a
        backoff of 1, 2, 4, 8 s: once (1 run in 3) B's first goal went out before the connection was up."""
        pubs = dict((t, n) for t, n in ros.master.call('getSystemState')[0])
        return all(sub.get_num_connections() >= len(pubs.get(sub.resolved_name, ())) for sub in self.subs)

    def since(self, kind, t):
        """Messages of ``kind`` received at sim time > t."""
        with self.lock:
            return [m for r, m in self.log[kind] if r > t]

    def stamped_after(self, kind, t):
        """Messages of ``kind`` whose own stamp is > t (sent after t)."""
        def stamp(m):
            return (m.goal_id.stamp if kind == 'goal' else m.header.stamp).to_sec()
        with self.lock:
            return [m for _, m in self.log[kind] if stamp(m) > t]

    def close(self):
        for s in self.subs:
            s.unregister()


def target(goal_msg):
    p = goal_msg.goal.target_pose.pose
    return (p.position.x, p.position.y, p.orientation.z, p.orientation.w)


def state_target(goal):
    return (goal['x'], goal['y'], math.sin(goal['yaw'] / 2), math.cos(goal['yaw'] / 2))


def now():
    return rospy.Time.now().to_sec()


def clock_skew() -> float:
    """How far another process's sim time may be ahead of this one's: each hears /clock on its own, so an output
    sent just before a freeze (under the lock the freeze takes) may carry a stamp a /clock period or two later than
    this process's clock read right after the freeze returned."""
    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config', 'simulator.yaml')) as f:
        return 2.0 / yaml.safe_load(f)['clock_frequency']


def publishes(ros, node, topic):
    pubs = dict((t, n) for t, n in ros.master.call('getSystemState')[0])
    return node in pubs.get(topic, [])


def test_three_instances_hand_over_a_search_and_a_patrol_goal(mission, mfg_params, ros):
    from migration_driver import LeaseDriver
    from migration_manager.core import state as codec
    rec = Recorder()
    driver = LeaseDriver('mfg', 'robot')
    procs = []

    def start(name):
        proc = ros.master.run(['rosrun', 'mfg', 'mfg'], name)
        procs.append(proc)
        driver.wait_standby(60)
        # warm: it follows its inputs (measurements in its state) and its move_base client is connected
        wait_until(lambda: len(driver.state()['measurements']) >= 5 and publishes(ros, '/mfg', '/move_base/goal'),
                   120, f'{name}: a warm standby', proc)
        return proc

    def stop(proc):
        before = len(rec.since('cancel', 0.0))
        ros.master.stop_child(proc)
        out = proc.output()
        assert 'Traceback' not in out, out[-3000:]
        return before

    try:
        # -- A: a standby, then the first active instance ------------------------------------------------
        a = start('mfg_a')
        s = driver.state()
        assert s['mode'] == 'IDLE' and s['goal'] is None and s['search'] is None and s['grid'] is not None
        assert s['detector']['n'] >= 5                                     # its detector follows the inputs
        assert not any(rec.since(k, 0.0) for k in ('goal', 'cancel', 'state', 'hotspot', 'activity')), rec.log
        # a state that does not fit is refused (the promotion with it fails), quietly, and changes nothing
        bad = dict(s, search={'ic': 5}, trigger=None)
        res = driver.control(command='promote', term=1, state=codec.encode('mfg', bad))
        assert not res.ok and 'mfg state: search.ic_mean: missing' in res.message, res
        assert driver.state() != bad and driver.state()['search'] is None
        t = now()
        driver.promote()                                                   # the first start: no state
        driver.wait_active(10)
        wait_until(lambda: rec.since('goal', t), 60, 'A: a goal', a)
        # patrol -> abnormal value -> search; freeze once a direction's goal has been sent
        def checking():
            states = [m for m in rec.since('state', t) if m.message.startswith('checking cell')]
            if not states:
                return None
            centre = states[-1]
            goals = rec.since('goal', t)
            return (centre, goals[-1]) if goals and goals[-1].goal_id.stamp >= centre.header.stamp else None
        checking_state, check_goal = wait_until(checking, 300, 'A: checking a direction', a)
        frozen = driver.freeze()
        t_freeze = now()
        assert frozen['mode'] == 'SEARCH' and frozen['trigger'] is not None and frozen['search'] is not None
        assert frozen['search']['unchecked'], frozen['search']
        assert frozen['goal']['kind'] == 'check' and frozen['goal']['cell'] == checking_state.goal_cell
        assert state_target(frozen['goal']) == pytest.approx(target(check_goal), abs=1e-9)
        assert len(frozen['measurements']) >= 20 and frozen['detector']['n'] > 0
        # move_base keeps the frozen instance's goal and finishes it; A sends and publishes nothing more
        done = wait_until(lambda: [r for r in rec.since('result', 0.0)
                                   if r.status.goal_id.id == check_goal.goal_id.id], 120, 'the check goal to end', a)
        assert done[0].status.status not in (done[0].status.PREEMPTED, done[0].status.RECALLED)   # not cancelled
        skew = clock_skew()
        assert not rec.since('cancel', t_freeze) and not rec.stamped_after('goal', t_freeze + skew)
        assert not rec.stamped_after('state', t_freeze + skew) and not rec.stamped_after('activity', t_freeze + skew)
        stop(a)
        assert not rec.since('cancel', t_freeze)                           # not at its shutdown either

        # -- B: takes A's search over and completes it ---------------------------------------------------
        b = start('mfg_b')
        # the hand-over outlasts the goal's goal_timeout (counted from A's send): B still drives it and measures
        wait_until(lambda: now() > frozen['goal']['sent'] + GOAL_TIMEOUT + 1.0, 60,
                   "the handed-over goal's goal_timeout to pass")
        wait_until(lambda: rec.connected(ros), 60, 'the recorder connected to B', b)
        t = now()
        driver.promote(frozen)
        driver.wait_active(10)
        first = wait_until(lambda: rec.since('goal', t), 60, 'B: its first goal', b)[0]
        assert target(first) == pytest.approx(state_target(frozen['goal']), abs=1e-9)   # the same target
        # its state message may arrive after its goal (two connections): wait for it
        resumed = wait_until(lambda: [m for m in rec.since('state', t) if m.mode == 'SEARCH'], 20,
                             'B: its SEARCH state', b)
        # the state is latched: a recorder whose connection to B's new publisher completes late gets B's newest
        # state, which may already be the next step of the same search: the handed-over cell checked, and, if it
        # was hotter, become the investigation cell with the old one checked (both seen on a fresh machine)
        ic, cell, r = frozen['search']['ic'], frozen['goal']['cell'], resumed[0]
        same_step = r.investigation_cell == ic and (
            r.message.startswith(f'resumed after a hand-over: hotspot search at investigation cell {ic}')
            or r.message.startswith(f'checking cell {cell} for IC {ic}'))
        next_step = r.last_cell == cell and (r.investigation_cell == ic or
                                             (r.investigation_cell == cell and ic in r.checked))
        assert same_step or next_step, resumed
        hotspot = wait_until(lambda: rec.since('hotspot', t), 300, 'B: the hotspot', b)[0]
        assert hotspot.cell_index == HEATER_CELL
        t_hot = now()
        # B cancelled nothing: the handed-over check goal was not cut short by A's goal_timeout
        assert not rec.since('cancel', t), rec.since('cancel', t)
        assert not [m for m in rec.since('state', t) if 'unreachable' in m.message]
        # back to the global goals; freeze B while it drives to one
        def patrol_goal():
            goals = rec.since('goal', t_hot)
            return goals[-1] if goals and rec.pose is not None else None
        patrol = wait_until(patrol_goal, 60, 'B: a patrol goal after the hotspot', b)
        frozen_b = driver.freeze()
        assert frozen_b['mode'] == 'PATROL' and frozen_b['search'] is None and frozen_b['trigger'] is None
        assert frozen_b['hotspots'] == [HEATER_CELL]
        assert frozen_b['goal']['kind'] == 'patrol' and frozen_b['goal']['interruptible']
        assert state_target(frozen_b['goal']) == pytest.approx(target(patrol), abs=1e-9)
        # rolled back: B itself is promoted again with its state and resumes the same goal
        t = now()
        driver.promote(frozen_b)
        driver.wait_active(10)
        again = wait_until(lambda: rec.since('goal', t), 60, 'B (promoted again): its goal', b)[0]
        assert target(again) == target(patrol)
        frozen_b = driver.freeze()
        t_freeze = now()
        assert frozen_b['goal']['kind'] == 'patrol' and state_target(frozen_b['goal']) == pytest.approx(
            target(patrol), abs=1e-9)
        stop(b)
        assert not rec.since('cancel', t_freeze) and not rec.stamped_after('goal', t_freeze + clock_skew())

        # -- C: takes B's patrol goal over; the patrol goes on; a lapse sends nothing ---------------------
        c = start('mfg_c')
        wait_until(lambda: rec.connected(ros), 60, 'the recorder connected to C', c)
        t = now()
        driver.promote(frozen_b)
        driver.wait_active(10)
        first = wait_until(lambda: rec.since('goal', t), 60, 'C: its first goal', c)[0]
        assert target(first) == target(patrol)                            # the same goal: move_base drives on
        wait_until(lambda: [g for g in rec.since('goal', t) if target(g) != target(patrol)], 180,
                   'C: the next patrol goal', c)
        driver.cut_off()                                                   # renewals no longer answered
        driver.wait_role('promoted', 10)                                   # lapsed: outputs closed
        t_lapse = now()
        # the goal in progress is not cancelled: move_base finishes it (a lapsed instance cancels nothing, not
        # even for an abnormal value or a timeout); no new goal while lapsed
        last = rec.since('goal', t)[-1]
        wait_until(lambda: [r for r in rec.since('result', 0.0) if r.status.goal_id.id == last.goal_id.id], 180,
                   'C: its last goal to end while lapsed', c)
        t_end = now()
        wait_until(lambda: now() > t_end + 8.0, 60, '8 s of sim time after the goal ended')
        assert not rec.since('cancel', t_lapse) and not rec.stamped_after('goal', t_lapse)
        assert not rec.stamped_after('state', t_lapse) and not rec.stamped_after('activity', t_lapse)
        with driver.lock:
            driver.answering = True                                        # renewals answered again
        driver.wait_active(10)
        wait_until(lambda: rec.stamped_after('goal', t_lapse), 60, 'C: goals again once its lease is back', c)
        assert c.alive()
        stop(c)
    finally:
        for p in procs:
            if p.alive():
                ros.master.stop_child(p)
        driver.close()
        rec.close()
