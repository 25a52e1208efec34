"""``global_goal_manager``: serves the next global goal cell (``~next_goal``) and publishes it (``global_goal``).

Movable by migration_manager: as a managed standby it follows ``cell_states`` but neither serves ``~next_goal``
nor publishes; its state (the policy's memory and the last goal) is handed over on promotion."""
from __future__ import annotations

import math
import threading
from typing import Any, Dict, Optional

import rospy
from geometry_msgs.msg import PoseStamped, Quaternion

import cnr_params
from cnr_maps.grid import MapcellGrid
from cnr_maps.pose import yaw_to_quaternion
from cnr_msgs.msg import CellStates
from cnr_msgs.srv import NextGoal, NextGoalResponse
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from global_goal_manager.core.policies import CellView, GoalManagerParams, read_params
from migration_manager.client import NOT_ACTIVE
from migration_manager.instance import Hooks, ManagedInstance, Retiring


class GoalManagerNode(Hooks):
    def __init__(self, p: GoalManagerParams) -> None:
        self.policy = p.policy
        self.frame_id = p.frame_id
        self.lock = threading.Lock()
        self.states = None
        self.last_goal: Optional[int] = None
        self.service: Optional[rospy.Service] = None
        self.retiring = Retiring()
        self.instance = ManagedInstance('global_goal_manager', self)
        self.pub = self.instance.publisher('global_goal', PoseStamped, queue_size=1, latch=True)
        rospy.Subscriber('cell_states', CellStates, self._on_states, queue_size=1)
        if not self.instance.managed:
            self.on_active()
        rospy.loginfo(f'global goal policy: {self.policy.name}'
                      f'{" (managed: standby until promoted)" if self.instance.managed else ""}')

    # -- migration state (README "Migration state") ----------------------------------------------
    def get_state(self) -> Dict[str, Any]:
        with self.lock:
            return {'policy': self.policy.name, 'policy_state': self.policy.state(), 'last_goal': self.last_goal}

    def set_state(self, state: Dict[str, Any]) -> None:
        if state.get('policy') != self.policy.name:
            raise ValueError(f'state of policy {state.get("policy")!r}, this instance runs {self.policy.name!r}')
        with self.lock:
            self.policy.restore(state.get('policy_state', {}))
            self.last_goal = state.get('last_goal')

    def on_active(self) -> None:
        self.retiring.close()                 # (promoted again before after_frozen ran: the same name)
        if self.service is None:
            self.service = rospy.Service('~next_goal', NextGoal, self._next_goal)

    def on_frozen(self) -> None:
        self.retiring.add(self.service)       # it answers "not active" until unregistered
        self.service = None

    def after_frozen(self) -> None:
        self.retiring.close()

    def _on_states(self, msg: CellStates) -> None:
        with self.lock:
            self.states = msg

    @quiet_at_shutdown
    def _next_goal(self, req) -> NextGoalResponse:
        if not self.instance.active:
            return NextGoalResponse(success=False, message=f'{NOT_ACTIVE} (standby, frozen or lease lapsed)',
                                    policy=self.policy.name)
        if not (math.isfinite(req.robot_x) and math.isfinite(req.robot_y)):
            return NextGoalResponse(success=False, message='robot position is not finite', policy=self.policy.name)
        with self.lock:
            states = self.states
        if states is None or not states.cells:
            return NextGoalResponse(success=False, message='no cell_states received yet', policy=self.policy.name)
        views = [CellView(c.index, c.row, c.col, c.center_x, c.center_y, c.last_visit.to_sec()) for c in states.cells]
        robot_cell = MapcellGrid.from_cell_states(states).index_of(req.robot_x, req.robot_y)
        with self.lock:
            index = self.policy.next_cell(views, robot_cell, (req.robot_x, req.robot_y))
        if index is None:
            return NextGoalResponse(success=False, message='no cell to choose', policy=self.policy.name)
        cell = states.cells[index]
        with self.lock:
            self.last_goal = index
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
