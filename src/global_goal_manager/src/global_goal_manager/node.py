"""``global_goal_manager``: serves the next global goal cell (``~next_goal``) and publishes it (``global_goal``)."""
from __future__ import annotations

import math
import threading

import rospy
from geometry_msgs.msg import PoseStamped, Quaternion

import cnr_params
from cnr_maps.grid import MapcellGrid
from cnr_maps.pose import yaw_to_quaternion
from cnr_msgs.msg import CellStates
from cnr_msgs.srv import NextGoal, NextGoalResponse
from cnr_params.ros import init_node, private_section, quiet_at_shutdown
from global_goal_manager.core.policies import CellView, GoalManagerParams, read_params


class GoalManagerNode:
    def __init__(self, p: GoalManagerParams) -> None:
        self.policy = p.policy
        self.frame_id = p.frame_id
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
        robot_cell = MapcellGrid.from_cell_states(states).index_of(req.robot_x, req.robot_y)
        index = self.policy.next_cell(views, robot_cell, (req.robot_x, req.robot_y))
        if index is None:
            return NextGoalResponse(success=False, message='no cell to choose', policy=self.policy.name)
        cell = states.cells[index]
        goal = PoseStamped()
        goal.header.stamp = rospy.Time.now()
        goal.header.frame_id = self.frame_id
        goal.pose.position.x, goal.pose.position.y = cell.center_x, cell.center_y
        yaw = math.atan2(cell.center_y - req.robot_y, cell.center_x - req.robot_x)
        goal.pose.orientation = Quaternion(*yaw_to_quaternion(yaw))
        self._announce(goal)
        return NextGoalResponse(success=True, message=f'cell {index} (col {cell.col}, row {cell.row})',
                                policy=self.policy.name, cell=cell, goal=goal)

    @quiet_at_shutdown
    def _announce(self, goal: PoseStamped) -> None:
        self.pub.publish(goal)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('global_goal_manager')
    GoalManagerNode(read_params(private_section('~')))
    rospy.spin()
