"""``goal_standin``: on the robot, drives the robot's own patrol goals while the goal source (mfg, possibly on the
cloud) leaves it standing still; hands back as soon as the source's goal is pursued again. See the package README
("The robot never stands still on the cloud's account").

Decisions: :class:`mfg.core.standin.Standin` (ROS-free); goals: the robot's own least-recently-visited cells
(:class:`mfg.core.fallback.LocalGoals`, the global goal manager's policy) from the time the robot was last in each
cell (its own pose: no measurement has to cross the link). Comms loss (:class:`mfg.core.standin.CommsLoss`, from
the multimaster bridge's ``link_quality``): with neither a goal of the source nor a good link for
``comms_loss.after``, its goal is the place where the link to the cloud was last good instead.
"""
from __future__ import annotations

import threading
import time
from typing import Optional, Tuple

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatusArray
from move_base_msgs.msg import MoveBaseAction
from nav_msgs.msg import Odometry
from std_msgs.msg import Bool

import cnr_params
from cnr_maps.grid import MapcellGrid
from cnr_msgs.msg import CellStates, LinkQuality, MfgActivity, SearchState
from cnr_params.ros import private_section
from cnr_runtime import init_node
from mfg.core.fallback import LocalGoals
from mfg.core.standin import ARRIVED, RESEND, SEND, Standin, StandinParams, read_params
from mfg.goals import facing_away, in_flight, move_base_goal, unacknowledged


class GoalStandin:
    """The node. ``lock`` guards the decision core, the goals and the grid (callbacks and the decision timer)."""

    def __init__(self, p: StandinParams) -> None:
        self.p = p
        self.lock = threading.Lock()
        prefix = rospy.get_name() + '-'          # actionlib's goal ids begin with the sending node's name
        self.core = Standin(p, lambda goal_id: goal_id.startswith(prefix))
        self.goals = LocalGoals()
        self.grid: Optional[MapcellGrid] = None
        self.pose: Optional[Tuple[float, float]] = None
        self.sent_wall: Optional[float] = None
        self.goals_sent = 0
        self.warned_no_grid = False
        self.client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        self.standing_pub = rospy.Publisher('~standing_in', Bool, queue_size=1, latch=True)
        self.standing_pub.publish(Bool(False))
        self.returning_pub = rospy.Publisher('~returning', Bool, queue_size=1, latch=True)
        self.returning_pub.publish(Bool(False))
        self.returning = False                   # a comms loss is on: driving back to the last good link, or there
        w = p.watch
        rospy.Subscriber('move_base/status', GoalStatusArray, self._on_status, queue_size=5)
        rospy.Subscriber(w.heartbeat_topic, MfgActivity, self._on_heartbeat, queue_size=1)
        rospy.Subscriber(w.state_topic, SearchState, self._on_state, queue_size=10)
        rospy.Subscriber('cell_states', CellStates, self._on_cells, queue_size=1)
        rospy.Subscriber(p.pose_topic, Odometry, self._on_pose, queue_size=1)
        if p.comms_loss.enabled:
            rospy.Subscriber(p.comms_loss.link_topic, LinkQuality, self._on_link, queue_size=10)
        rospy.Timer(rospy.Duration(1.0 / p.rate), self._step)

    @staticmethod
    def _now() -> float:
        return rospy.Time.now().to_sec()

    # -- inputs ------------------------------------------------------------------------------------------
    def _on_status(self, msg: GoalStatusArray) -> None:
        with self.lock:
            self.core.path.status(self._now(), [(s.goal_id.id, s.status) for s in msg.status_list])

    def _on_heartbeat(self, _msg: MfgActivity) -> None:
        with self.lock:
            self.core.path.heartbeat(self._now())

    def _on_state(self, msg: SearchState) -> None:
        with self.lock:
            self.core.path.source_mode(self._now(), msg.mode)

    def _on_cells(self, msg: CellStates) -> None:
        with self.lock:
            if self.grid is None and msg.cells:
                self.grid = MapcellGrid.from_cell_states(msg)

    def _on_link(self, msg: LinkQuality) -> None:
        with self.lock:
            comms = self.core.comms
            good = comms.judge.good(msg.peer, msg.alive, msg.loss, msg.rtt, msg.received)
            comms.link(self._now(), good, self.pose)

    def _on_pose(self, msg: Odometry) -> None:
        x, y = msg.pose.pose.position.x, msg.pose.pose.position.y
        with self.lock:
            self.pose = (x, y)
            cell = self.grid.index_of(x, y) if self.grid is not None else None
            if cell is not None:
                self.goals.visited(cell, msg.header.stamp.to_sec())

    # -- decisions ---------------------------------------------------------------------------------------
    def _step(self, _event) -> None:
        now = self._now()
        with self.lock:
            if self.core.handed_back():
                rospy.loginfo('goal_standin: the goal source\'s goal is pursued again: handed back')
                self.standing_pub.publish(Bool(False))
            flying = in_flight(self.client)
            resend = flying and unacknowledged(self.client) and time.monotonic() - self.sent_wall > self.p.ack_timeout
            if self._comms_loss(now, flying, resend):
                return
            if flying and not resend:
                return                           # its goal is being driven to (or its acknowledgement awaited)
            if not self.core.due(now):
                return
            if self.grid is None or self.pose is None:
                if not self.warned_no_grid:
                    rospy.logwarn('goal_standin: the robot stands still, but no grid (cell_states) or pose yet: '
                                  'no goal of its own to give')
                    self.warned_no_grid = True
                return
            index = self.goals.next_cell(self.grid, self.pose)
            if index is None:
                return
            c = self.grid.cell(index)
            first = self._send(c.center_x, c.center_y)
            if first:
                path = self.core.path
                heard = 'never' if path.last_heartbeat is None else f'{now - path.last_heartbeat:.1f} s ago'
                rospy.logwarn(f'goal_standin: no goal for {now - path.standing_since(now):.1f} s and the goal source '
                              f'(mode {path.mode or "unknown"}, last heard {heard}) does not hold the robot: '
                              f'driving its own {LocalGoals.name} goals until the source gives one again')
            rospy.loginfo(f'goal_standin: goal {self.goals_sent}: cell {index} (col {c.col}, row {c.row}) at '
                          f'({c.center_x:.1f}, {c.center_y:.1f})')

    def _send(self, x: float, y: float) -> bool:
        """Send its goal at (x, y); True if it is its first since it last handed back."""
        goal = move_base_goal(x, y, facing_away(self.pose, x, y), self.p.frame_id)
        goal.target_pose.header.stamp = rospy.Time.now()
        # sent before anything else (logging included): the less time between the decision and the goal, the
        # less chance that a goal of the source sent meanwhile is preempted by this one
        self.client.send_goal(goal)
        self.sent_wall = time.monotonic()
        first = not self.core.standing_in
        self.core.sent()
        self.goals_sent += 1
        if first:
            self.standing_pub.publish(Bool(True))
        return first

    def _comms_loss(self, now: float, flying: bool, resend: bool) -> bool:
        """The comms-loss behaviour's step; True while it decides the stand-in's goal (driving back to the last
        place with a good link, or waiting there for the link). ``flying``: the goal last sent is not over;
        ``resend``: ... but move_base has not acknowledged it within ``ack_timeout``."""
        comms = self.core.comms
        action = comms.step(now, flying, resend)
        if action is None:
            if self.returning:
                self.returning = False
                self.returning_pub.publish(Bool(False))
                why = 'waited there without it' if comms.given_up else 'the link or the source\'s goal is back'
                rospy.logwarn(f'goal_standin: comms loss over ({why}): the ordinary stand-in goes on')
            return False
        x, y = comms.target
        if action in (SEND, RESEND):
            self._send(x, y)
        if action == ARRIVED:
            rospy.loginfo(f'goal_standin: back at the last place with a good link ({x:.1f}, {y:.1f}): waiting for '
                          f'the link')
        elif action == SEND:
            if not self.returning:
                self.returning = True
                self.returning_pub.publish(Bool(True))
            rospy.logwarn(f'goal_standin: comms loss: no goal of the source and no good link to '
                          f'{self.p.comms_loss.peer} for {now - comms.lost_since(now):.1f} s: goal {self.goals_sent}: '
                          f'back to ({x:.1f}, {y:.1f}), the last place with a good link')
        return True


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('goal_standin')
    GoalStandin(read_params(private_section('~')))
    rospy.spin()
