"""goal_standin in the corridor mission on a real master with real nodes: the goal source (mfg) disappears in the
middle of a patrol and the robot gets a stand-in goal within 2 s of standing still; mfg comes back, its first goal
preempts the stand-in's, and the stand-in gives no goal while mfg patrols. The mission report's standstill is the
interval the robot stood still."""
import json
import os
import subprocess
import threading
import time

import pytest

from cnr_harness import wait_until
from mfg_missions import patrol_only_mission

rospy = pytest.importorskip('rospy')

PURSUED = (0, 1, 6, 7)        # actionlib_msgs/GoalStatus PENDING, ACTIVE, PREEMPTING, RECALLING
BOUND = 2.0                   # s: a robot left without a goal gets one within (outage + 2 s)


@pytest.fixture
def mission(ros, workspace, tmp_path):
    """The corridor without heaters (mfg only patrols), with the stand-in, in real time."""
    proc, report = patrol_only_mission(ros, workspace, tmp_path, 'mfg_standin', 'real_time_factor:=1',
                                       'goal_standin:=true')
    yield proc, report
    proc.stop()


class Statuses:
    """move_base's status lists: (stamp [s], [(goal id, status), ...])."""

    def __init__(self) -> None:
        from actionlib_msgs.msg import GoalStatusArray
        self.lock = threading.Lock()
        self.lists = []
        self.sub = rospy.Subscriber('/move_base/status', GoalStatusArray, self._on, queue_size=50)

    def _on(self, msg) -> None:
        with self.lock:
            self.lists.append((msg.header.stamp.to_sec(), [(s.goal_id.id, s.status) for s in msg.status_list]))

    def since(self, index: int):
        with self.lock:
            return list(enumerate(self.lists))[index:]

    def first(self, index: int, predicate):
        """(list index, stamp) of the first list from ``index`` on for which ``predicate(goals)`` holds."""
        for i, (stamp, goals) in self.since(index):
            if predicate(goals):
                return i, stamp
        return None


def pursued_by(who):
    return lambda goals: any(g.startswith(f'/{who}-') and st in PURSUED for g, st in goals)


def idle(goals):
    return not any(st in PURSUED for _g, st in goals)


def test_the_robot_gets_a_stand_in_goal_when_mfg_is_gone_and_mfg_takes_over_again(mission, ros):
    from actionlib_msgs.msg import GoalID
    from std_msgs.msg import Bool
    proc, report = mission
    statuses = Statuses()
    standing = []
    standing_sub = rospy.Subscriber('/goal_standin/standing_in', Bool, lambda m: standing.append(m.data), queue_size=10)
    cancel = rospy.Publisher('/move_base/cancel', GoalID, queue_size=1)
    restarted = None
    try:
        wait_until(lambda: statuses.first(0, pursued_by('mfg')), 180, 'a goal of mfg pursued', proc)
        assert not statuses.first(0, pursued_by('goal_standin'))        # mfg drives: no stand-in
        # the goal source disappears (as a cloud-side mfg cut off), and its goal is dropped
        subprocess.run(['rosnode', 'kill', '/mfg'], env=ros.master.env, check=True, capture_output=True, timeout=30)
        killed_wall = time.time()
        mark = len(statuses.since(0))
        wait_until(lambda: cancel.get_num_connections() > 0, 30, 'move_base listening to cancels')
        cancel.publish(GoalID())                                        # every goal
        _i, t_idle = wait_until(lambda: statuses.first(mark, idle), 30, 'move_base without a goal', proc)
        i_standin, t_standin = wait_until(lambda: statuses.first(mark, pursued_by('goal_standin')), 60,
                                          'a stand-in goal', proc)
        assert 0.0 < t_standin - t_idle <= BOUND, (t_idle, t_standin)
        wait_until(lambda: standing and standing[-1] is True, 10, 'goal_standin reporting that it stands in')

        # mfg is back: its first goal preempts the stand-in's, and the stand-in gives no more
        restarted = ros.master.run(['rosrun', 'mfg', 'mfg', '__name:=mfg'], log_name='mfg_standin_mfg_again')
        i_back, t_back = wait_until(lambda: statuses.first(i_standin, pursued_by('mfg')), 120,
                                    'a goal of the restarted mfg', proc)
        wait_until(lambda: standing and standing[-1] is False, 10, 'goal_standin reporting that it handed back')
        stamp_now = wait_until(lambda: statuses.first(i_back, lambda g: True), 10, 'a status list')[1]
        wait_until(lambda: statuses.lists[-1][0] >= stamp_now + 20.0, 120, '20 s of the patrol after the hand-back',
                   proc)
        after = [goals for _i, (stamp, goals) in statuses.since(i_back) if stamp > t_back + 0.5]
        assert not any(pursued_by('goal_standin')(g) for g in after), 'the stand-in drove while mfg patrolled'
        assert any(pursued_by('mfg')(g) for g in after)

        # the report: the longest standstill with a task pending is the one the stand-in ended
        subprocess.run(['rosservice', 'call', '/mission_monitor/finish'], env=ros.master.env, check=True,
                       capture_output=True, timeout=30)
        summary_path = os.path.join(report, 'summary.json')
        wait_until(lambda: os.path.exists(summary_path), 120, 'the mission report', proc)
        st = json.load(open(summary_path))['standstill']
        print(f'stand-in goal {t_standin - t_idle:.2f} s after move_base had none; summary standstill {st}')
        assert st['longest'] == pytest.approx(t_standin - t_idle, abs=0.5) and st['longest'] <= BOUND + 0.2, st
        assert killed_wall - 1.0 <= st['longest_start'] <= time.time(), (killed_wall, st)
        assert st['task_pending_from_sim'] is not None and st['intervals'] >= 1, st
        out = proc.output()
        assert out.count('goal_standin: no goal for') == 1, out[-3000:]          # logged once per stand-in
        assert 'Traceback' not in out, out[-3000:]
    finally:
        statuses.sub.unregister()
        standing_sub.unregister()
        cancel.unregister()
        if restarted is not None:
            ros.master.stop_child(restarted)
