"""move_base goals as mfg and goal_standin send them (thin ROS helpers shared by both nodes)."""
from __future__ import annotations

import math
from typing import Optional, Tuple

import actionlib
from actionlib.action_client import CommState
from geometry_msgs.msg import Quaternion
from move_base_msgs.msg import MoveBaseGoal

from cnr_maps.pose import yaw_to_quaternion


def move_base_goal(x: float, y: float, yaw: float, frame_id: str) -> MoveBaseGoal:
    """A move_base goal at (x, y) [m] in ``frame_id``, heading ``yaw`` [rad] (its stamp is set when sent)."""
    target = MoveBaseGoal()
    target.target_pose.header.frame_id = frame_id
    target.target_pose.pose.position.x, target.target_pose.pose.position.y = x, y
    target.target_pose.pose.orientation = Quaternion(*yaw_to_quaternion(yaw))
    return target


def facing_away(pose: Optional[Tuple[float, float]], x: float, y: float) -> float:
    """The heading [rad] from the robot's position to (x, y) (0 while the position is unknown)."""
    return math.atan2(y - pose[1], x - pose[0]) if pose is not None else 0.0


def unacknowledged(client: actionlib.SimpleActionClient) -> bool:
    """The goal last sent has not been seen in the server's status list yet (it may have been lost on its way:
    actionlib sends a goal once, and a link outage can swallow it)."""
    gh = client.gh
    return gh is not None and gh.get_comm_state() == CommState.WAITING_FOR_GOAL_ACK


def in_flight(client: actionlib.SimpleActionClient) -> bool:
    """The goal last sent is not over yet at the client (sent, pending, active, being cancelled)."""
    gh = client.gh
    return gh is not None and gh.get_comm_state() not in (CommState.DONE, CommState.WAITING_FOR_RESULT)
