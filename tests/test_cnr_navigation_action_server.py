"""cnr_navigation.action_server: a goal left active by an execute callback the node's shutdown ended.

At the end of a mission in CI, move_base could see this: the shutdown closed the action's topics while a goal was
being pursued, the execute callback ended quietly (``quiet_at_shutdown``), and the execute thread then tried to
abort the goal: a warning, "publish() to a closed topic" with its traceback, and an invalid transition. At the
shutdown nothing can be published any more, so the thread must just end.

Runs in a child interpreter with a real master (a rospy shutdown cannot be undone in this one)."""
import subprocess
import sys

import pytest

pytest.importorskip('rospy')

SCRIPT = r'''
import threading
import actionlib, rospy
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from cnr_navigation.action_server import TakeoverActionServer

rospy.init_node('action_server_shutdown', disable_signals=True)
executing = threading.Event()

def execute(goal):
    executing.set()
    rospy.signal_shutdown('the node is killed')      # closes every topic; the goal stays active

server = TakeoverActionServer('move_base', MoveBaseAction, execute)
server.start_with()
client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
assert client.wait_for_server(rospy.Duration(30)), 'no server'
goal = MoveBaseGoal()
goal.target_pose.header.frame_id = 'map'
goal.target_pose.pose.orientation.w = 1.0
client.send_goal(goal)
assert executing.wait(30), 'the goal was never executed'
server.execute_thread.join(30)
print('execute thread ended' if not server.execute_thread.is_alive() else 'execute thread still running')
'''


def test_a_shutdown_during_a_goal_ends_the_execute_thread_quietly(ros):
    out = subprocess.run([sys.executable, '-c', SCRIPT], capture_output=True, text=True, timeout=120,
                         env=ros.master.env)
    both = out.stdout + out.stderr
    assert out.returncode == 0, both[-3000:]
    assert 'execute thread ended' in out.stdout, both[-3000:]
    for bad in ('Traceback', 'did not set the goal to a terminal status', 'closed topic', 'To transition'):
        assert bad not in both, both[-3000:]
