"""``mfg`` (measurement feedback goal): patrol the global goals, and locate a hotspot when a value is abnormal.

Drives through ``move_base`` (actionlib); asks ``global_goal_manager/next_goal`` for global goals; watches
``mapcell_measurements`` (stored measurements, their cell assigned by local_mapcell_manager); publishes
``hotspot`` and ``~state``. See the package README.

Movable by migration_manager: as a managed standby it follows its inputs (its detector, visit times and
measurements stay warm) but sends no goal and publishes nothing; on promotion it takes over the frozen
instance's state (``core/memory.py``) and resumes its goal or search. A frozen or lapsed instance never cancels
the move_base goal: its successor's identical goal replaces it.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Dict, Optional, Tuple

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseAction
from nav_msgs.msg import Odometry

import cnr_params
from cnr_msgs.msg import CellStates, Hotspot, MergedMeasurement, MfgActivity, SearchState
from cnr_maps.grid import MapcellGrid
from cnr_msgs.srv import NextGoal, NextGoalResponse
from cnr_params.ros import private_section
from cnr_runtime import init_node
from mfg.core.fallback import LocalGoals
from mfg.core.memory import Goal, Memory
from mfg.core.params import MfgParams, read_params
from mfg.core.search import HotspotSearch
from mfg.goals import facing_away, move_base_goal, unacknowledged
from migration_manager.client import MovableServiceProxy
from migration_manager.instance import Hooks, ManagedInstance


_TERMINAL = (GoalStatus.SUCCEEDED, GoalStatus.ABORTED, GoalStatus.REJECTED, GoalStatus.PREEMPTED, GoalStatus.RECALLED)
_POLL = 0.02          # wall s between looks at the lease while the outputs are closed
_RECALLS = 3          # a goal move_base refused before it started is sent again this often at most


class MfgNode(Hooks):
    """The node. Threads: rospy's callbacks (inputs), :meth:`run` (the behaviour), the managed instance's
    (promotion, freeze, state). ``lock`` guards :attr:`memory` and the state message; the instance's own lock is
    taken before it (``set_state``/``get_state`` are called under it), so no code here asks the instance for
    ``active`` while holding ``lock``.

    Each unit of work (a patrol goal, a search) runs under an *epoch*: a freeze or a new state starts a new one,
    and a unit whose epoch is over returns at once, leaving move_base's goal alone.
    """

    def __init__(self, p: MfgParams) -> None:
        self.p = p
        self.lock = threading.Lock()
        self.memory = Memory(p.detector, p.neighbourhood, p.suppress_radius)
        self.epoch = 0
        self.pose: Optional[Tuple[float, float]] = None
        self.state_msg = SearchState(mode='IDLE', goal_cell=-1, investigation_cell=-1, investigation_mean=math.nan,
                                     last_temperature=math.nan, last_cell=-1)
        self.instance = ManagedInstance('mfg', self)
        self.client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        self.next_goal = MovableServiceProxy(p.next_goal_service, NextGoal)     # one connection, follows it
        self.goal_manager_reachable = True
        self.state_pub = self.instance.publisher('~state', SearchState, queue_size=10, latch=True)
        self.hotspot_pub = self.instance.publisher('hotspot', Hotspot, queue_size=1, latch=True)
        self.activity_pub = self.instance.publisher('~activity', MfgActivity, queue_size=1, latch=True)
        rospy.Timer(rospy.Duration(1.0 / p.activity_rate), self._publish_activity)
        rospy.Subscriber('cell_states', CellStates, self._on_cells, queue_size=1)
        rospy.Subscriber(p.pose_topic, Odometry, self._on_pose, queue_size=1)
        rospy.Subscriber('mapcell_measurements', MergedMeasurement, self._on_measurement, queue_size=100)
        if self.instance.managed:
            rospy.loginfo('mfg: managed, a standby until promoted (inputs followed, no goal, no output)')

    # -- migration (the package README, "Migration state") ---------------------------------------------
    def get_state(self) -> Dict[str, Any]:
        with self.lock:
            return self.memory.to_state()

    def set_state(self, state: Dict[str, Any]) -> None:
        with self.lock:
            try:
                replayed = self.memory.restore(state)
            except ValueError:
                raise
            except Exception as exc:            # a state that does not fit in a way the checks did not foresee
                raise ValueError(f'mfg state does not fit: {type(exc).__name__}: {exc}') from None
            self.epoch += 1
            m = self.memory
            summary = (f'mode {m.mode}, {len(m.measurements)} measurements ({replayed} of its own replayed), '
                       f'{"a search at IC " + str(m.search.ic) if m.search else "no search"}, '
                       f'goal {"cell " + str(m.goal.cell) + " (" + m.goal.kind + ")" if m.goal else "none"}')
        rospy.loginfo(f'mfg: state taken over: {summary}')

    def on_active(self) -> None:
        """:meth:`run` waits for ``instance.active`` and resumes from :attr:`memory`; the activity report goes out
        at once (a consumer sees the new instance without waiting for the next ``activity_rate`` tick)."""
        if getattr(self, 'activity_pub', None) is not None:
            self._publish_activity(None)

    def on_frozen(self) -> None:
        with self.lock:
            self.epoch += 1              # the current unit of work ends; move_base keeps its goal

    def _live(self, epoch: int) -> bool:
        return self.epoch == epoch and not rospy.is_shutdown()

    def _wait_active(self) -> Optional[int]:
        """Wait until this instance may produce output; returns the epoch (None at shutdown)."""
        while not rospy.is_shutdown():
            epoch = self.epoch
            if self.instance.active:
                return epoch
            time.sleep(_POLL)
        return None

    def _wait_open(self, epoch: int) -> bool:
        """Wait through a lapse of the lease; False once the epoch is over (frozen, a new state) or at shutdown."""
        while self._live(epoch):
            if self.instance.active:
                return True
            time.sleep(_POLL)
        return False

    def _output(self, epoch: int, action: Callable[[], None], wait: bool = True) -> bool:
        """Carry out ``action`` (an output: a goal, a cancel, a publication) if this instance may.

        Waits through a lapse if ``wait`` (else gives up at once). The last look is taken under :attr:`lock`,
        which a freeze needs to take the state: an output either happens before the state is taken (and the state
        shows it) or not at all.
        """
        if wait and not self._wait_open(epoch):
            return False
        if not wait and not self.instance.active:
            return False
        with self.lock:
            if self.epoch != epoch or self.instance.frozen:      # a plain attribute: no instance lock here
                return False
            action()
        return True

    # -- inputs (followed by a standby too) -------------------------------------------------------------
    def _on_cells(self, msg: CellStates) -> None:
        with self.lock:
            if self.memory.grid is None and msg.cells:
                self.memory.grid = MapcellGrid.from_cell_states(msg)

    def _on_pose(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def _on_measurement(self, msg: MergedMeasurement) -> None:
        received = rospy.Time.now().to_sec()       # receipt time: a late delivery is a gap
        with self.lock:
            self.memory.activity.input(received)
            grid = self.memory.grid
            if grid is None or not 0 <= msg.cell < len(grid) or not math.isfinite(msg.temperature):
                return
            # the cell was assigned by local_mapcell_manager when it stored the measurement
            self.state_msg.last_temperature, self.state_msg.last_cell = msg.temperature, msg.cell
            self.memory.observe(msg.header.stamp.to_sec(), msg.cell, msg.temperature)

    def _publish_activity(self, _event) -> None:
        if not self.instance.active:
            return
        now = rospy.Time.now()
        with self.lock:
            r = self.memory.activity.report(now.to_sec())
            if self.instance.frozen:
                return
            msg = MfgActivity(measurements=r.measurements, longest_input_gap=r.longest_input_gap,
                              goal_waits=r.goal_waits, goal_wait_total=r.goal_wait_total,
                              goal_wait_longest=r.goal_wait_longest, longest_idle=r.longest_idle)
            msg.header.stamp = now
            self.activity_pub.publish(msg)

    # -- helpers -------------------------------------------------------------------------------
    def publish_state(self, mode: str, message: str, epoch: int, search: Optional[HotspotSearch] = None,
                      goal_cell: int = -1) -> bool:
        """Record the mode and publish ``~state`` (if the outputs are open; a lapse does not wait).
        False if the epoch is over."""
        open_ = self.instance.active
        with self.lock:
            if self.epoch != epoch:
                return False
            self.memory.mode = mode
            s = self.state_msg
            s.header.stamp = rospy.Time.now()
            s.mode, s.message, s.goal_cell = mode, message, goal_cell
            if search is not None:
                s.investigation_cell, s.investigation_mean = search.ic, search.ic_mean
                s.checked, s.unchecked = list(search.checked), list(search.unchecked)
            elif mode == 'PATROL':
                s.investigation_cell, s.investigation_mean, s.checked, s.unchecked = -1, math.nan, [], []
            if open_ and not self.instance.frozen:
                self.state_pub.publish(s)
        rospy.loginfo(message)
        return True

    def new_goal(self, cell: int, interruptible: bool, kind: str, xy: Optional[Tuple[float, float]] = None) -> Goal:
        """A goal to ``cell``'s centre (or ``xy``), facing away from the robot."""
        x, y = xy if xy is not None else self.cell_centre(cell)
        return Goal(x, y, facing_away(self.pose, x, y), cell, interruptible, kind, rospy.Time.now().to_sec())

    def drive(self, goal: Goal, epoch: int) -> str:
        """Drive to ``goal``; returns 'succeeded', 'failed', 'interrupted' (abnormal value while patrolling) or
        'stopped' (the epoch is over: frozen, a new state, shutdown; the goal is left to move_base)."""
        with self.lock:
            if self.epoch != epoch:
                return 'stopped'
            self.memory.goal = goal            # before it is sent: a state taken from now on holds it
        target = move_base_goal(goal.x, goal.y, goal.yaw, self.p.frame_id)
        sent_wall = time.monotonic()

        def send() -> None:
            nonlocal sent_wall
            target.target_pose.header.stamp = rospy.Time.now()
            self.client.send_goal(target)
            sent_wall = time.monotonic()
        if not self._output(epoch, send):
            return 'stopped'
        # the timeout counts from this instance's send: a goal handed over (sent earlier by another instance)
        # gets its whole goal_timeout again, so a hand-over, however long it took, never cancels it at once
        deadline = max(goal.sent, rospy.Time.now().to_sec()) + self.p.goal_timeout
        recalls = 0
        while self._live(epoch):
            # the server's status list may say the goal ended while its result never came: it was published while
            # the link was down (results are not latched; the status is repeated) - the goal is over all the same
            if self.client.wait_for_result(rospy.Duration(0.1)) or self.client.get_state() in _TERMINAL:
                # refused before it started (RECALLED; mfg cancels only by returning): a goal sent while the
                # link was down arrives stamped older than the goal move_base has meanwhile (the robot's
                # stand-in's), and move_base keeps the newer one. The same goal again, stamped now
                if self.client.get_state() == GoalStatus.RECALLED and recalls < _RECALLS and \
                        self._output(epoch, send, wait=False):
                    recalls += 1
                    rospy.logwarn(f'move_base refused the goal to cell {goal.cell} before it started: sent again')
                    continue
                return self._outcome(goal)
            # move_base never listed the goal: it was lost on its way (actionlib sends a goal once; an outage
            # swallows it). The same goal again, as a new one
            if unacknowledged(self.client) and time.monotonic() - sent_wall > self.p.goal_ack_timeout:
                if self._output(epoch, send, wait=False):
                    rospy.logwarn(f'move_base did not acknowledge the goal to cell {goal.cell} within '
                                  f'{self.p.goal_ack_timeout:g} s: sent again')
            # an interruption or a timeout cancels the goal only while the outputs are open (not in a lapse)
            if goal.interruptible and self.memory.trigger is not None:
                if self._output(epoch, self.client.cancel_goal, wait=False):
                    return 'interrupted'
            elif rospy.Time.now().to_sec() > deadline:
                if self._output(epoch, self.client.cancel_goal, wait=False):
                    return 'failed'
        return 'stopped'

    def _outcome(self, goal: Goal) -> str:
        """'succeeded' or 'failed' for a goal that ended. A goal LOST (move_base's status list stopped listing it:
        it ended while the link was down, longer ago than the list keeps ended goals) counts as reached when the
        robot is in the goal's cell."""
        state = self.client.get_state()
        if state == GoalStatus.SUCCEEDED:
            return 'succeeded'
        if state == GoalStatus.LOST and self.pose is not None:
            with self.lock:
                grid = self.memory.grid
            if grid is not None and grid.index_of(*self.pose) == goal.cell:
                return 'succeeded'
        return 'failed'

    def measure(self, cell: int, epoch: int) -> Optional[float]:
        """Average temperature in ``cell`` after settling: NaN if nothing could be measured, None if the epoch
        ended meanwhile."""
        start = rospy.Time.now().to_sec()
        t_from = start + self.p.settle_time
        deadline = t_from + self.p.measure_timeout
        while self._live(epoch):
            with self.lock:
                values = self.memory.values(cell, since=t_from)
            if len(values) >= self.p.min_measurements:
                return sum(values) / len(values)
            if rospy.Time.now().to_sec() > deadline:
                return sum(values) / len(values) if values else math.nan
            rospy.sleep(0.1)
        return None

    def cell_centre(self, index: int) -> Tuple[float, float]:
        c = self.memory.grid.cell(index)
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
        ok, res, _sent = self.next_goal.call(timeout, x, y)      # registration and answer within the timeout
        if not ok:
            problem = res.message if isinstance(res, NextGoalResponse) else str(res)
        elif not res.success:
            problem = res.message
        with self.lock:
            self.memory.activity.waited(rospy.Time.now().to_sec() - asked)
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
        with self.lock:
            grid = self.memory.grid
            index = self.memory.local_goals.next_cell(grid, (x, y))
        if index is None:
            return None, LocalGoals.name
        c = grid.cell(index)
        return (c.index, c.col, c.row, c.center_x, c.center_y), LocalGoals.name

    def patrol_once(self, epoch: int) -> None:
        if not self._wait_open(epoch):         # no question to the goal manager while the outputs are closed
            return
        x, y = self.pose if self.pose else (0.0, 0.0)
        goal, policy = self._global_goal(x, y)
        if not self._live(epoch):
            return
        if goal is None:
            rospy.sleep(1.0)
            return
        index, col, row, gx, gy = goal
        self.patrol_goal(self.new_goal(index, True, 'patrol', (gx, gy)),
                         f'global goal: cell {index} (col {col}, row {row}) at ({gx:.1f}, {gy:.1f}) [{policy}]', epoch)

    def patrol_goal(self, goal: Goal, message: str, epoch: int) -> None:
        if not self.publish_state('PATROL', message, epoch, goal_cell=goal.cell):
            return
        outcome = self.drive(goal, epoch)
        if outcome == 'stopped':
            return
        with self.lock:
            if self.epoch == epoch:
                self.memory.goal = None
        if outcome == 'failed':
            rospy.logwarn(f'global goal cell {goal.cell} not reached')

    def search(self, epoch: int) -> None:
        """Locate the hotspot of the trigger, or go on with the search (and its goal) a state brought."""
        with self.lock:
            trigger, s, goal = self.memory.trigger, self.memory.search, self.memory.goal
        cell = trigger.cell
        if s is None:
            resumed = goal is not None and goal.kind == 'approach'
            if not self.publish_state('SEARCH', f'{"resumed after a hand-over: " if resumed else ""}abnormal '
                                                f'temperature {trigger.temperature:.2f} degC in cell {cell}: '
                                                f'locating the hotspot', epoch):
                return
            if self.drive(goal if resumed else self.new_goal(cell, False, 'approach'), epoch) == 'stopped':
                return
            ic_mean = self.measure(cell, epoch)
            if ic_mean is None:
                return
            if math.isnan(ic_mean):
                ic_mean = trigger.temperature
            known = {}
            if trigger.previous is not None:
                with self.lock:
                    prev_values = self.memory.values(trigger.previous)[-self.p.min_measurements:]
                if prev_values:
                    known[trigger.previous] = sum(prev_values) / len(prev_values)
            with self.lock:
                if self.epoch != epoch:
                    return
                s = HotspotSearch(self.memory.neighbours, cell, ic_mean, trigger.previous, known)
                self.memory.search, self.memory.goal = s, None
            goal = None
            message = f'investigation cell {s.ic} ({s.ic_mean:.2f} degC); unchecked {s.unchecked}'
        else:
            message = (f'resumed after a hand-over: hotspot search at investigation cell {s.ic} ({s.ic_mean:.2f} '
                       f'degC); checked {s.checked}, unchecked {s.unchecked}')
        if not self.publish_state('SEARCH', message, epoch, search=s):
            return
        # a direction that was being checked when the state was handed over is checked first (same goal)
        pending = goal if goal is not None and goal.kind == 'check' and goal.cell in s.unchecked else None
        while not s.done:
            if not self._live(epoch):
                return
            if pending is not None:
                target_goal, pending = pending, None
            else:
                px, py = self.pose if self.pose else self.cell_centre(cell)
                target = s.next_target(lambda i: math.hypot(self.cell_centre(i)[0] - px, self.cell_centre(i)[1] - py))
                target_goal = self.new_goal(target, False, 'check')
            target = target_goal.cell
            if not self.publish_state('SEARCH', f'checking cell {target} for IC {s.ic}', epoch, search=s,
                                      goal_cell=target):
                return
            outcome = self.drive(target_goal, epoch)
            if outcome == 'stopped':
                return
            if outcome != 'succeeded':
                with self.lock:
                    if self.epoch != epoch:
                        return
                    s.unreachable(target)
                    self.memory.goal = None
                self.publish_state('SEARCH', f'cell {target} unreachable: marked checked', epoch, search=s)
                continue
            mean = self.measure(target, epoch)
            if mean is None:
                return
            with self.lock:
                if self.epoch != epoch:
                    return
                step = s.report(target, mean)
                self.memory.goal = None
            self.publish_state('SEARCH', f'cell {target}: {step.mean:.2f} degC ({step.outcome}); IC {s.ic} '
                                         f'{s.ic_mean:.2f} degC; unchecked {s.unchecked}', epoch, search=s)
        hot = self.memory.grid.cell(s.ic)
        msg = Hotspot(cell_index=s.ic, row=hot.row, col=hot.col, x=hot.center_x, y=hot.center_y,
                      temperature=s.ic_mean, search_duration=rospy.Time.now().to_sec() - trigger.t,
                      cells_checked=sum(1 for h in s.history if h.outcome != 'hotter') + len(s.ic_history) - 1)
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = self.p.frame_id

        def declare() -> None:
            self.hotspot_pub.publish(msg)
            m = self.memory
            m.hotspots.append(s.ic)
            m.trigger, m.search, m.goal = None, None, None   # values around it no longer trigger a search
        if not self._output(epoch, declare):
            return
        self.publish_state('DONE', f'HOTSPOT in cell {s.ic} (col {hot.col}, row {hot.row}) at '
                                   f'({hot.center_x:.1f}, {hot.center_y:.1f}): {s.ic_mean:.2f} degC after '
                                   f'{msg.search_duration:.0f} s; back to the global goals', epoch, search=s)

    def run(self) -> None:
        while not rospy.is_shutdown() and (self.memory.grid is None or self.pose is None):
            rospy.sleep(0.2)
        rospy.loginfo('waiting for move_base')
        while not rospy.is_shutdown() and not self.client.wait_for_server(rospy.Duration(1.0)):
            pass
        while not rospy.is_shutdown():
            epoch = self._wait_active()        # a standby, a lapse, a frozen instance: no goal, no output
            if epoch is None:
                return
            with self.lock:
                mode, trigger, goal = self.memory.mode, self.memory.trigger, self.memory.goal
            if mode == 'IDLE' and not self.publish_state('PATROL', 'patrolling the global goals', epoch):
                continue
            if trigger is not None:
                self.search(epoch)
            elif goal is not None and goal.kind == 'patrol':     # handed over mid-goal: the same goal again
                self.patrol_goal(goal, f'resumed after a hand-over: global goal cell {goal.cell} at '
                                       f'({goal.x:.1f}, {goal.y:.1f})', epoch)
            else:
                self.patrol_once(epoch)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('mfg')
    node = MfgNode(read_params(private_section('~')))
    try:
        node.run()
    except rospy.ROSInterruptException:
        pass
