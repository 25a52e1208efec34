"""``mfg`` (measurement feedback goal): patrol the global goals, and locate a hotspot when a value is abnormal.

Drives through ``move_base`` (actionlib); asks ``global_goal_manager/next_goal`` for global goals; watches
``mapcell_measurements`` (stored measurements, their cell assigned by local_mapcell_manager); publishes
``hotspot`` and ``~state``. See the package README.
"""
from __future__ import annotations

import math
import threading
from collections import deque
from typing import Deque, List, Optional, Tuple

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Quaternion
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from nav_msgs.msg import Odometry

import cnr_params
from cnr_msgs.msg import CellStates, Hotspot, MergedMeasurement, MfgActivity, SearchState
from cnr_maps.grid import MapcellGrid
from cnr_maps.pose import yaw_to_quaternion
from cnr_msgs.srv import NextGoal
from cnr_params.ros import call_with_timeout, init_node, private_section
from mfg.core.activity import ActivityTracker
from mfg.core.detector import Detector
from mfg.core.fallback import LocalGoals
from mfg.core.params import MfgParams, read_params
from mfg.core.search import HotspotSearch


_TERMINAL = (GoalStatus.SUCCEEDED, GoalStatus.ABORTED, GoalStatus.REJECTED, GoalStatus.PREEMPTED, GoalStatus.RECALLED)


class MfgNode:
    def __init__(self, p: MfgParams) -> None:
        self.p = p
        self.detector = Detector(p.detector)
        self.lock = threading.Lock()
        self.grid: Optional[MapcellGrid] = None
        self.pose: Optional[Tuple[float, float]] = None
        self.measurements: Deque[Tuple[float, int, float]] = deque(maxlen=5000)   # (t, cell, temperature)
        self.trigger: Optional[Tuple[float, int, float]] = None
        self.cell_trail: List[int] = []       # distinct cells in visiting order
        self.hotspots: List[int] = []
        self.state = SearchState(mode='IDLE', goal_cell=-1, investigation_cell=-1, investigation_mean=math.nan,
                                 last_temperature=math.nan, last_cell=-1)
        self.client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        self.next_goal = rospy.ServiceProxy(p.next_goal_service, NextGoal)     # one proxy for every goal
        self.local_goals = LocalGoals()
        self.goal_manager_reachable = True
        self.state_pub = rospy.Publisher('~state', SearchState, queue_size=10, latch=True)
        self.hotspot_pub = rospy.Publisher('hotspot', Hotspot, queue_size=1, latch=True)
        self.activity = ActivityTracker()
        self.activity_pub = rospy.Publisher('~activity', MfgActivity, queue_size=1, latch=True)
        rospy.Timer(rospy.Duration(1.0 / p.activity_rate), self._publish_activity)
        rospy.Subscriber('cell_states', CellStates, self._on_cells, queue_size=1)
        rospy.Subscriber(p.pose_topic, Odometry, self._on_pose, queue_size=1)
        rospy.Subscriber('mapcell_measurements', MergedMeasurement, self._on_measurement, queue_size=100)

    # -- inputs --------------------------------------------------------------------------------
    def _on_cells(self, msg: CellStates) -> None:
        if self.grid is None and msg.cells:
            self.grid = MapcellGrid.from_cell_states(msg)

    def _on_pose(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def _on_measurement(self, msg: MergedMeasurement) -> None:
        self.activity.input(rospy.Time.now().to_sec())       # receipt time: a late delivery is a gap
        if self.grid is None or not 0 <= msg.cell < len(self.grid) or not math.isfinite(msg.temperature):
            return
        cell = msg.cell            # assigned by local_mapcell_manager when it stored the measurement
        t = msg.header.stamp.to_sec()
        with self.lock:
            self.state.last_temperature, self.state.last_cell = msg.temperature, cell
            self.measurements.append((t, cell, msg.temperature))
            self.local_goals.visited(cell, t)
            if not self.cell_trail or self.cell_trail[-1] != cell:
                self.cell_trail.append(cell)
            abnormal = self.detector.observe(msg.temperature)
            suppressed = any(self.grid.chebyshev(cell, h) <= self.p.suppress_radius for h in self.hotspots)
            if abnormal and not suppressed and self.trigger is None and self.state.mode == 'PATROL':
                self.trigger = (t, cell, msg.temperature)

    def _publish_activity(self, _event) -> None:
        now = rospy.Time.now()
        r = self.activity.report(now.to_sec())
        msg = MfgActivity(measurements=r.measurements, longest_input_gap=r.longest_input_gap,
                          goal_waits=r.goal_waits, goal_wait_total=r.goal_wait_total,
                          goal_wait_longest=r.goal_wait_longest, longest_idle=r.longest_idle)
        msg.header.stamp = now
        self.activity_pub.publish(msg)

    # -- helpers -------------------------------------------------------------------------------
    def publish_state(self, mode: str, message: str, search: Optional[HotspotSearch] = None,
                      goal_cell: int = -1) -> None:
        with self.lock:
            s = self.state
            s.header.stamp = rospy.Time.now()
            s.mode, s.message, s.goal_cell = mode, message, goal_cell
            if search is not None:
                s.investigation_cell, s.investigation_mean = search.ic, search.ic_mean
                s.checked, s.unchecked = list(search.checked), list(search.unchecked)
            elif mode == 'PATROL':
                s.investigation_cell, s.investigation_mean, s.checked, s.unchecked = -1, math.nan, [], []
            self.state_pub.publish(s)
        rospy.loginfo(message)

    def drive(self, x: float, y: float, interruptible: bool) -> str:
        """Drive to (x, y); returns 'succeeded', 'failed' or 'interrupted' (abnormal value while patrolling)."""
        goal = MoveBaseGoal()
        goal.target_pose.header.frame_id = self.p.frame_id
        goal.target_pose.header.stamp = rospy.Time.now()
        goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = x, y
        yaw = math.atan2(y - self.pose[1], x - self.pose[0]) if self.pose is not None else 0.0
        goal.target_pose.pose.orientation = Quaternion(*yaw_to_quaternion(yaw))
        self.client.send_goal(goal)
        deadline = rospy.Time.now().to_sec() + self.p.goal_timeout
        while not rospy.is_shutdown():
            if self.client.wait_for_result(rospy.Duration(0.1)):
                return 'succeeded' if self.client.get_state() == GoalStatus.SUCCEEDED else 'failed'
            # the server's status list says the goal ended, but its result never came: it was published while
            # the link was down (results are not latched; the status is repeated) - the goal is over all the same
            if self.client.get_state() in _TERMINAL:
                return 'succeeded' if self.client.get_state() == GoalStatus.SUCCEEDED else 'failed'
            if interruptible and self.trigger is not None:
                self.client.cancel_goal()
                return 'interrupted'
            if rospy.Time.now().to_sec() > deadline:
                self.client.cancel_goal()
                return 'failed'
        return 'failed'

    def measure(self, cell: int) -> float:
        """Average temperature in ``cell`` after settling: NaN if nothing could be measured."""
        start = rospy.Time.now().to_sec()
        t_from = start + self.p.settle_time
        deadline = t_from + self.p.measure_timeout
        while not rospy.is_shutdown():
            with self.lock:
                values = [v for t, c, v in self.measurements if c == cell and t >= t_from]
            if len(values) >= self.p.min_measurements:
                return sum(values) / len(values)
            if rospy.Time.now().to_sec() > deadline:
                return sum(values) / len(values) if values else math.nan
            rospy.sleep(0.1)
        return math.nan

    def cell_centre(self, index: int) -> Tuple[float, float]:
        c = self.grid.cell(index)
        return c.center_x, c.center_y

    # -- behaviours ----------------------------------------------------------------------------
    def _global_goal(self, x: float, y: float) -> Tuple[Optional[Tuple[int, int, int, float, float]], str]:
        """Next global goal (index, col, row, x, y) and the policy that chose it.

        Asks the global goal manager with a timeout (it may run on the cloud); if it does not answer, the
        robot's own least-recently-visited goal (logged once per outage). The robot never waits on the cloud.
        """
        timeout = self.p.next_goal_timeout
        problem = ''
        asked = rospy.Time.now().to_sec()
        try:
            rospy.wait_for_service(self.p.next_goal_service, timeout)
            ok, res = call_with_timeout(self.next_goal, timeout, x, y)
            if not ok:
                problem = str(res)
            elif not res.success:
                problem = res.message
        except rospy.ROSException as exc:          # not registered within the timeout
            problem = str(exc)
        self.activity.waited(rospy.Time.now().to_sec() - asked)
        if not problem:
            if not self.goal_manager_reachable:
                rospy.loginfo('global goal manager answers again: back to its goals')
                self.goal_manager_reachable = True
            c = res.cell
            return (c.index, c.col, c.row, c.center_x, c.center_y), res.policy
        if self.goal_manager_reachable:
            rospy.logwarn(f'global goal manager unavailable ({problem}): patrolling with the robot\'s own '
                          f'least-recently-visited goals until it answers again')
            self.goal_manager_reachable = False
        index = self.local_goals.next_cell(self.grid, (x, y))
        if index is None:
            return None, LocalGoals.name
        c = self.grid.cell(index)
        return (c.index, c.col, c.row, c.center_x, c.center_y), LocalGoals.name

    def patrol_once(self) -> None:
        x, y = self.pose if self.pose else (0.0, 0.0)
        goal, policy = self._global_goal(x, y)
        if goal is None:
            rospy.sleep(1.0)
            return
        index, col, row, gx, gy = goal
        self.publish_state('PATROL', f'global goal: cell {index} (col {col}, row {row}) at ({gx:.1f}, {gy:.1f}) '
                                     f'[{policy}]', goal_cell=index)
        outcome = self.drive(gx, gy, interruptible=True)
        if outcome == 'failed' and not rospy.is_shutdown():     # a goal cancelled by our own shutdown is no news
            rospy.logwarn(f'global goal cell {index} not reached')

    def search(self) -> None:
        t0, cell, temp = self.trigger
        with self.lock:
            trail = list(self.cell_trail)
        previous = next((c for c in reversed(trail[:-1]) if c != cell), None)
        self.publish_state('SEARCH', f'abnormal temperature {temp:.2f} degC in cell {cell}: locating the hotspot')
        conn = self.p.neighbourhood
        cx, cy = self.cell_centre(cell)
        self.drive(cx, cy, interruptible=False)
        ic_mean = self.measure(cell)
        if math.isnan(ic_mean):
            ic_mean = temp
        known = {}
        if previous is not None:
            with self.lock:
                prev_values = [v for t, c, v in self.measurements if c == previous]
            if prev_values:
                known[previous] = sum(prev_values[-self.p.min_measurements:]) / len(prev_values[-self.p.min_measurements:])
        s = HotspotSearch(lambda i: self.grid.neighbours(i, conn), cell, ic_mean, previous, known)
        self.publish_state('SEARCH', f'investigation cell {s.ic} ({s.ic_mean:.2f} degC); unchecked {s.unchecked}',
                           search=s)
        while not s.done and not rospy.is_shutdown():
            px, py = self.pose if self.pose else (cx, cy)
            target = s.next_target(lambda i: math.hypot(self.cell_centre(i)[0] - px, self.cell_centre(i)[1] - py))
            tx, ty = self.cell_centre(target)
            self.publish_state('SEARCH', f'checking cell {target} for IC {s.ic}', search=s, goal_cell=target)
            if self.drive(tx, ty, interruptible=False) != 'succeeded':
                s.unreachable(target)
                self.publish_state('SEARCH', f'cell {target} unreachable: marked checked', search=s)
                continue
            step = s.report(target, self.measure(target))
            self.publish_state('SEARCH', f'cell {target}: {step.mean:.2f} degC ({step.outcome}); IC {s.ic} '
                                         f'{s.ic_mean:.2f} degC; unchecked {s.unchecked}', search=s)
        hot = self.grid.cell(s.ic)
        msg = Hotspot(cell_index=s.ic, row=hot.row, col=hot.col, x=hot.center_x, y=hot.center_y,
                      temperature=s.ic_mean, search_duration=rospy.Time.now().to_sec() - t0,
                      cells_checked=sum(1 for h in s.history if h.outcome != 'hotter') + len(s.ic_history) - 1)
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = self.p.frame_id
        self.hotspot_pub.publish(msg)
        self.hotspots.append(s.ic)
        self.publish_state('DONE', f'HOTSPOT in cell {s.ic} (col {hot.col}, row {hot.row}) at '
                                   f'({hot.center_x:.1f}, {hot.center_y:.1f}): {s.ic_mean:.2f} degC after '
                                   f'{msg.search_duration:.0f} s; back to the global goals', search=s)
        with self.lock:
            self.trigger = None        # values around a known hotspot no longer trigger a search

    def run(self) -> None:
        while not rospy.is_shutdown() and (self.grid is None or self.pose is None):
            rospy.sleep(0.2)
        rospy.loginfo('waiting for move_base')
        while not rospy.is_shutdown() and not self.client.wait_for_server(rospy.Duration(1.0)):
            pass
        self.publish_state('PATROL', 'patrolling the global goals')
        while not rospy.is_shutdown():
            if self.trigger is not None:
                self.search()
            else:
                self.patrol_once()


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('mfg')
    node = MfgNode(read_params(private_section('~')))
    try:
        node.run()
    except rospy.ROSInterruptException:
        pass
