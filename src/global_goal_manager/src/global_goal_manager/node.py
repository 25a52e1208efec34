"""``global_goal_manager``: serves the next global goal cell (``~next_goal``) and publishes it (``global_goal``)."""
from __future__ import annotations

import math
import threading

import rospy
from geometry_msgs.msg import PoseStamped

import cnr_params
from cnr_msgs.msg import CellStates
from cnr_msgs.srv import NextGoal, NextGoalResponse
from cnr_params.ros import private_section
from global_goal_manager.core.policies import CellView, make_policy


class GoalManagerNode:
    def __init__(self, policy_name: str, frame_id: str, source: str) -> None:
        self.policy = make_policy(policy_name, source, 'global_goal_manager.policy')
        self.frame_id = frame_id
        self.lock = threading.Lock()
        self.states = None
        self.pub = rospy.Publisher('global_goal', PoseStamped, queue_size=1, latch=True)
        rospy.Subscriber('cell_states', CellStates, self._on_states, queue_size=1)
        rospy.Service('~next_goal', NextGoal, self._next_goal)
        rospy.loginfo(f'global goal policy: {self.policy.name}')

    def _on_states(self, msg: CellStates) -> None:
        with self.lock:
            self.states = msg

    def _next_goal(self, req) -> NextGoalResponse:
        if not (math.isfinite(req.robot_x) and math.isfinite(req.robot_y)):
            return NextGoalResponse(success=False, message='robot position is not finite', policy=self.policy.name)
        with self.lock:
            states = self.states
        if states is None or not states.cells:
            return NextGoalResponse(success=False, message='no cell_states received yet', policy=self.policy.name)
        views = [CellView(c.index, c.row, c.col, c.center_x, c.center_y, c.last_visit.to_sec()) for c in states.cells]
        robot_cell = next((c.index for c in states.cells if c.min_x < req.robot_x <= c.max_x
                           and c.min_y < req.robot_y <= c.max_y), None)
        index = self.policy.next_cell(views, robot_cell, (req.robot_x, req.robot_y))
        if index is None:
            return NextGoalResponse(success=False, message='no cell to choose', policy=self.policy.name)
        cell = states.cells[index]
        goal = PoseStamped()
        goal.header.stamp = rospy.Time.now()
        goal.header.frame_id = self.frame_id
        goal.pose.position.x, goal.pose.position.y = cell.center_x, cell.center_y
        yaw = math.atan2(cell.center_y - req.robot_y, cell.center_x - req.robot_x)
        goal.pose.orientation.z, goal.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        self.pub.publish(goal)
        return NextGoalResponse(success=True, message=f'cell {index} (col {cell.col}, row {cell.row})',
                                policy=self.policy.name, cell=cell, goal=goal)


@cnr_params.exit_on_config_error
def main() -> None:
    rospy.init_node('global_goal_manager')
    p = private_section('~')
    sec = p.section('global_goal_manager', {})
    GoalManagerNode(sec.string('policy', 'least_recently_visited'), p.string('frame_id', 'map'), p.source)
    rospy.spin()
