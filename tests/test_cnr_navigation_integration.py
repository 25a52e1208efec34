"""move_base-compatible navigation with the simulator on a real master: goals through the action."""
import math
import threading

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


@pytest.fixture(scope='module')
def robot(ros):
    import actionlib
    from move_base_msgs.msg import MoveBaseAction
    proc = ros.master.roslaunch('cnr_bringup', 'robot.launch', 'real_time_factor:=3.0')
    client = actionlib.SimpleActionClient('move_base', MoveBaseAction)

    def ready():
        assert proc.alive(), proc.output()[-3000:]
        return not rospy.Time.now().is_zero() and client.wait_for_server(rospy.Duration(0.5))
    wait_until(ready, 120, 'the move_base action server')
    yield client
    proc.stop()


def goal_msg(x, y, yaw=0.0, frame='map'):
    from move_base_msgs.msg import MoveBaseGoal
    g = MoveBaseGoal()
    g.target_pose.header.frame_id = frame
    g.target_pose.header.stamp = rospy.Time.now()
    g.target_pose.pose.position.x, g.target_pose.pose.position.y = x, y
    g.target_pose.pose.orientation.z, g.target_pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return g


def run_goal(client, goal, wall_timeout=240):
    client.send_goal(goal)
    wait_until(lambda: client.wait_for_result(rospy.Duration(0.2)), wall_timeout, 'the goal result')
    return client.get_state(), client.get_goal_status_text()


def true_pose():
    from nav_msgs.msg import Odometry
    m = rospy.wait_for_message('base_pose_ground_truth', Odometry, timeout=30)
    return m.pose.pose.position


def test_goal_in_corridor_reached_within_0_2_m(robot):
    from actionlib_msgs.msg import GoalStatus
    state, text = run_goal(robot, goal_msg(4.0, 0.4))
    assert state == GoalStatus.SUCCEEDED, text
    p = true_pose()
    assert math.hypot(p.x - 4.0, p.y - 0.4) <= 0.2


def test_goal_in_wall_is_aborted_with_text(robot):
    from actionlib_msgs.msg import GoalStatus
    state, text = run_goal(robot, goal_msg(4.0, 1.05))       # inside the upper wall
    assert state == GoalStatus.ABORTED
    assert 'obstacle' in text or 'plan' in text, text


def test_goal_outside_the_map_is_aborted(robot):
    from actionlib_msgs.msg import GoalStatus
    state, text = run_goal(robot, goal_msg(500.0, 0.0))
    assert state == GoalStatus.ABORTED and 'off the global costmap' in text, text


def test_nan_goal_rejected_and_node_keeps_running(robot):
    from actionlib_msgs.msg import GoalStatus
    state, text = run_goal(robot, goal_msg(float('nan'), 0.0))
    assert state == GoalStatus.ABORTED and 'NaN' in text, text
    assert robot.wait_for_server(rospy.Duration(1.0))


def test_make_plan_service(robot):
    from nav_msgs.srv import GetPlan
    from geometry_msgs.msg import PoseStamped
    rospy.wait_for_service('move_base/make_plan', 30)
    start, goal = PoseStamped(), PoseStamped()
    for p, x in ((start, 1.0), (goal, 9.0)):
        p.header.frame_id = 'map'
        p.pose.position.x = x
        p.pose.orientation.w = 1.0
    plan = rospy.ServiceProxy('move_base/make_plan', GetPlan)(start, goal, 0.0).plan
    assert len(plan.poses) > 100
    assert plan.poses[-1].pose.position.x == pytest.approx(9.0, abs=0.05)


def test_controller_runs_at_20_hz_after_reconfigure(robot):
    import dynamic_reconfigure.client
    from actionlib_msgs.msg import GoalStatus
    from geometry_msgs.msg import Twist
    dynamic_reconfigure.client.Client('move_base', timeout=30).update_configuration({'controller_frequency': 20.0})
    stamps = []
    lock = threading.Lock()

    def on_cmd(_msg):
        with lock:
            stamps.append(rospy.Time.now().to_sec())
    sub = rospy.Subscriber('mobile_base/commands/velocity', Twist, on_cmd, queue_size=100)
    state, text = run_goal(robot, goal_msg(1.5, -0.3, math.pi))
    sub.unregister()
    assert state == GoalStatus.SUCCEEDED, text
    with lock:
        span = stamps[-1] - stamps[0]
        rate = (len(stamps) - 1) / span
    assert rate > 12.0, f'{rate:.1f} Hz command rate'
