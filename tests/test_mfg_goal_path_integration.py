"""mfg's goal path recovers by itself (real master, real nodes, the corridor patrol in real time): mfg reaches
move_base through a relay in this test that can lose a goal (as an outage does) or deliver it late, stamped older
than a goal move_base got meanwhile (as the robot's stand-in gives). A lost goal is sent again after
``goal_ack_timeout``; a late goal move_base refuses is sent again at once and replaces the newer one."""
import os
import subprocess
import threading

import pytest

from cnr_harness import wait_until
from mfg_missions import patrol_only_mission

rospy = pytest.importorskip('rospy')


class Relay:
    """``/mb_relay`` (mfg's action name here) <-> ``/move_base``: goals and cancels one way, status, feedback and
    result the other. ``drop`` goals are lost; while ``holding``, goals wait until :meth:`release`."""

    def __init__(self) -> None:
        from actionlib_msgs.msg import GoalID, GoalStatusArray
        from move_base_msgs.msg import MoveBaseActionFeedback, MoveBaseActionGoal, MoveBaseActionResult
        self.lock = threading.Lock()
        self.drop, self.holding, self.held = 0, False, []
        self.seen = []          # every goal mfg sent: (id, stamp [s], x, y, what happened to it)
        self.statuses = []      # move_base's: [(id, status), ...]
        self.goal_pub = rospy.Publisher('/move_base/goal', MoveBaseActionGoal, queue_size=10)
        cancel_pub = rospy.Publisher('/move_base/cancel', GoalID, queue_size=10)
        status_pub = rospy.Publisher('/mb_relay/status', GoalStatusArray, queue_size=10)
        feedback_pub = rospy.Publisher('/mb_relay/feedback', MoveBaseActionFeedback, queue_size=10)
        result_pub = rospy.Publisher('/mb_relay/result', MoveBaseActionResult, queue_size=10)

        def on_status(msg):
            with self.lock:
                self.statuses.append([(s.goal_id.id, s.status) for s in msg.status_list])
            status_pub.publish(msg)
        self.subs = [rospy.Subscriber('/mb_relay/goal', MoveBaseActionGoal, self._on_goal, queue_size=10),
                     rospy.Subscriber('/mb_relay/cancel', GoalID, cancel_pub.publish, queue_size=10),
                     rospy.Subscriber('/move_base/status', GoalStatusArray, on_status, queue_size=10),
                     rospy.Subscriber('/move_base/feedback', MoveBaseActionFeedback, feedback_pub.publish,
                                      queue_size=10),
                     rospy.Subscriber('/move_base/result', MoveBaseActionResult, result_pub.publish, queue_size=10)]
        self.pubs = [self.goal_pub, cancel_pub, status_pub, feedback_pub, result_pub]

    def _on_goal(self, msg) -> None:
        p = msg.goal.target_pose.pose.position
        with self.lock:
            if self.drop:
                self.drop -= 1
                fate = 'lost'
            elif self.holding:
                self.held.append(msg)
                fate = 'held'
            else:
                fate = 'delivered'
            self.seen.append((msg.goal_id.id, msg.goal_id.stamp.to_sec(), p.x, p.y, fate))
        if fate == 'delivered':
            self.goal_pub.publish(msg)

    def release(self) -> None:
        with self.lock:
            held, self.held, self.holding = self.held, [], False
        for msg in held:
            self.goal_pub.publish(msg)

    def pursued(self, goal_id) -> bool:
        with self.lock:
            return bool(self.statuses) and any(g == goal_id and st in (0, 1) for g, st in self.statuses[-1])

    def status_of(self, goal_id):
        with self.lock:
            for g, st in reversed(self.statuses[-1] if self.statuses else []):
                if g == goal_id:
                    return st
        return None

    def close(self) -> None:
        for s in self.subs:
            s.unregister()
        for p in self.pubs:
            p.unregister()


@pytest.fixture
def mission(ros, workspace, tmp_path):
    """The patrol-only corridor without mfg; mfg started by the test with its move_base behind the relay."""
    proc, _report = patrol_only_mission(ros, workspace, tmp_path, 'mfg_goal_path', 'real_time_factor:=1', 'mfg:=false')
    relay = Relay()
    for f in ('mfg.yaml', os.path.join('scenarios', 'corridor.yaml')):
        subprocess.run(['rosparam', 'load', os.path.join(workspace, 'config', f), '/mfg'], env=ros.master.env,
                       check=True, capture_output=True, timeout=30)
    relay.drop = 1                                   # mfg's first goal is lost on its way
    mfg = ros.master.run(['rosrun', 'mfg', 'mfg', '__name:=mfg', 'move_base:=/mb_relay'], log_name='mfg_goal_path_mfg')
    yield proc, mfg, relay
    relay.close()
    ros.master.stop_child(mfg)
    proc.stop()


def test_a_lost_goal_is_sent_again_and_a_goal_refused_as_stale_replaces_the_newer_one(mission, ros):
    from move_base_msgs.msg import MoveBaseActionGoal
    proc, mfg, relay = mission
    # the first goal lost: the same target again, as a new goal, and move_base pursues it
    wait_until(lambda: len(relay.seen) >= 2, 120, 'mfg sending its lost goal again', mfg)
    (lost_id, _t, x0, y0, fate0), (again_id, _t1, x1, y1, fate1) = relay.seen[:2]
    assert (fate0, fate1) == ('lost', 'delivered') and lost_id != again_id and (x0, y0) == (x1, y1), relay.seen
    wait_until(lambda: relay.pursued(again_id), 30, 'move_base pursuing the goal sent again', mfg)
    assert 'did not acknowledge the goal' in mfg.output()

    # its next goal comes late: held in the relay while another goal (as the stand-in's) reaches move_base
    with relay.lock:
        relay.holding = True
    n = len(relay.seen)
    newer = MoveBaseActionGoal()
    newer.goal.target_pose.header.frame_id = 'map'
    newer.goal.target_pose.pose.position.x, newer.goal.target_pose.pose.position.y = x1, y1
    newer.goal.target_pose.pose.orientation.w = 1.0

    def send_newer():
        newer.header.stamp = newer.goal_id.stamp = newer.goal.target_pose.header.stamp = rospy.Time.now()
        newer.goal_id.id = f'/stand_in_test-{newer.goal_id.stamp.to_sec():.3f}'
        relay.goal_pub.publish(newer)
        return newer.goal_id.id
    first_newer = send_newer()             # preempts mfg's goal: mfg asks for the next one, which the relay holds
    wait_until(lambda: len(relay.seen) > n, 60, "mfg's next goal", mfg)
    late_id, late_stamp, xl, yl, _ = relay.seen[n]
    wait_until(lambda: rospy.Time.now().to_sec() > late_stamp + 0.5, 10, 'time to pass')
    newest = send_newer()                  # stamped after the held goal
    wait_until(lambda: relay.pursued(newest), 30, 'move_base pursuing the newer goal', mfg)
    relay.release()
    # move_base refuses the late goal (older than its current one); mfg sends it again, and that one wins
    wait_until(lambda: relay.status_of(late_id) == 8, 30, 'the late goal refused (RECALLED)', mfg)
    wait_until(lambda: len(relay.seen) > n + 1, 30, 'mfg sending the refused goal again', mfg)
    again2_id, again2_stamp, xa, ya, fate = relay.seen[n + 1]
    assert fate == 'delivered' and (xa, ya) == (xl, yl) and again2_stamp > late_stamp, relay.seen
    wait_until(lambda: relay.pursued(again2_id), 30, "move_base pursuing mfg's goal again", mfg)
    # move_base lists the goal as pending first and preempts the one it pursues on its next cycle
    wait_until(lambda: relay.status_of(newest) in (2, 3, 4, None), 30, "the newer goal preempted by mfg's", mfg)
    assert first_newer != newest
    out = mfg.output()
    assert 'refused the goal to cell' in out and 'Traceback' not in out, out[-3000:]
