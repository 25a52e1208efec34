"""move_base's state machine without ROS: PLANNING / CONTROLLING / CLEARING (``move_base.cpp``).

:class:`MoveBaseCore` follows ``MoveBase::executeCycle`` and ``MoveBase::planThread`` of
navigation@noetic-devel, with the same patience timers, oscillation detection, recovery
sequence and abort texts. Time is passed in explicitly (seconds, sim time in the node), so the
whole machine runs under a fake clock in unit tests.

The planner runs either inline (``sync_planner=True``: due plans are made at the start of a
:meth:`MoveBaseCore.cycle`) or in a separate thread that calls :meth:`MoveBaseCore.run_planner`
when :meth:`MoveBaseCore.planner_due` says so (the node does this, as move_base's planner thread).

Goals move_base would accept but that can never be reached are refused at once with a clear text
(NaN coordinates, invalid quaternion, outside the map, inside an obstacle) instead of spending
the planner patience and every recovery on them.
"""
from __future__ import annotations

import enum
import logging
import math
import threading
from dataclasses import dataclass
from typing import Callable, List, Optional, Protocol, Sequence, Tuple

import numpy as np

from cnr_navigation.core.geometry import Pose2D, Quaternion, quaternion_problem, quaternion_to_yaw
from cnr_navigation.core.planner import PlanningError
from cnr_navigation.core.recovery import Recovery

log = logging.getLogger('rosout')

Velocity = Tuple[float, float]
ZERO: Velocity = (0.0, 0.0)

TEXT_GOAL_REACHED = 'Goal reached.'
TEXT_NO_PLAN = 'Failed to find a valid plan. Even after executing recovery behaviors.'
TEXT_NO_CONTROL = 'Failed to find a valid control. Even after executing recovery behaviors.'
TEXT_OSCILLATING = 'Robot is oscillating. Even after executing recovery behaviors.'
TEXT_BAD_QUATERNION = 'Aborting on goal because it was sent with an invalid quaternion'
TEXT_BAD_COORDINATES = 'Aborting on goal because it was sent with NaN or infinite coordinates'
TEXT_PASS_PLAN = 'Failed to pass global plan to the controller.'


class NavState(enum.Enum):
    PLANNING = 0
    CONTROLLING = 1
    CLEARING = 2


class RecoveryTrigger(enum.Enum):
    PLANNING_R = 0
    CONTROLLING_R = 1
    OSCILLATION_R = 2


@dataclass
class MoveBaseConfig:
    """``~*`` parameters of move_base that the state machine uses (s, Hz, m).

    Defaults are move_base's code defaults; the TurtleBot values live in
    ``config/navigation/move_base_params.yaml``.
    """

    controller_frequency: float
    planner_frequency: float
    controller_patience: float
    planner_patience: float
    max_planning_retries: int
    oscillation_timeout: float
    oscillation_distance: float
    recovery_behavior_enabled: bool
    clearing_rotation_allowed: bool
    conservative_reset_dist: float
    shutdown_costmaps: bool
    make_plan_clear_costmap: bool
    make_plan_add_unreachable_goal: bool


class NavigationBackend(Protocol):
    """What the state machine drives: pose, global planner and local controller."""

    def robot_pose(self) -> Optional[Pose2D]:
        """Robot pose in the global frame (None when tf has none)."""

    def check_goal(self, goal: Pose2D) -> None:
        """Raise :class:`PlanningError` if ``goal`` can never be reached (off map, in a wall)."""

    def make_plan(self, start: Pose2D, goal: Pose2D) -> np.ndarray:
        """(N, 3) plan in the global frame; raise :class:`PlanningError` when there is none."""

    def set_plan(self, plan: np.ndarray) -> bool:
        """Hand a new plan to the local controller."""

    def compute_velocity(self) -> Optional[Velocity]:
        """One local-controller cycle: a command, or None if no valid one."""

    def is_goal_reached(self) -> bool:
        """The local controller's goal check."""

    def sensors_current(self) -> bool:
        """False when sensor data for the local costmap is out of date."""


@dataclass
class Outcome:
    """A terminal result for the current goal: ``status`` 'SUCCEEDED' or 'ABORTED' and its text."""

    status: str
    text: str


@dataclass
class CycleResult:
    """What one control cycle asks the node to do.

    Attributes:
        cmd: velocity to publish (None: publish nothing this cycle).
        outcome: set when the goal ended.
        recovery: (index, total, name) when a recovery behaviour started this cycle.
        pose: the robot pose used (for feedback), if known.
    """

    cmd: Optional[Velocity]
    outcome: Optional[Outcome] = None
    recovery: Optional[Tuple[int, int, str]] = None
    pose: Optional[Pose2D] = None


@dataclass
class _Timers:
    last_valid_plan: float = 0.0
    last_valid_control: float = 0.0
    last_oscillation_reset: float = 0.0
    next_plan_time: float = -math.inf


def goal_problem(x: float, y: float, z: float, q: Quaternion) -> Optional[Tuple[str, str]]:
    """(status text, log detail) if a goal pose cannot be used at all, else None."""
    if not all(math.isfinite(v) for v in (x, y, z)):
        return TEXT_BAD_COORDINATES, f'goal position ({x}, {y}, {z}) is not finite'
    problem = quaternion_problem(q)
    if problem is not None:
        return TEXT_BAD_QUATERNION, problem
    return None


class MoveBaseCore:
    """The move_base state machine; see the module docstring.

    Args:
        cfg: move_base parameters.
        backend: pose, planner and controller.
        recoveries: the recovery sequence (default: conservative clear, rotate, aggressive clear, rotate).
        sync_planner: plan inline in :meth:`cycle` instead of in a separate thread.
    """

    def __init__(self, cfg: MoveBaseConfig, backend: NavigationBackend, recoveries: Sequence[Recovery] = (),
                 sync_planner: bool = True) -> None:
        self.cfg = cfg
        self.backend = backend
        self.recoveries: List[Recovery] = list(recoveries)
        self.sync_planner = sync_planner
        self.lock = threading.RLock()
        self.goal: Optional[Pose2D] = None
        self.plan: Optional[np.ndarray] = None
        self._epoch = 0
        self._reset_state()

    # -- state ---------------------------------------------------------------------------------
    def _reset_state(self) -> None:
        self.state = NavState.PLANNING
        self.recovery_index = 0
        self.recovery_trigger = RecoveryTrigger.PLANNING_R
        self.run_planner_flag = False
        self.new_global_plan = False
        self.planning_retries = 0
        self.active_recovery: Optional[Recovery] = None
        self.oscillation_pose: Optional[Pose2D] = None
        self.t = _Timers()

    @property
    def active(self) -> bool:
        return self.goal is not None

    def reset(self) -> None:
        """Drop the goal (preempt, abort, success): ``MoveBase::resetState``."""
        with self.lock:
            self._epoch += 1
            self.goal = None
            self.plan = None
            self._reset_state()

    def new_goal(self, x: float, y: float, q: Quaternion, now: float, z: float = 0.0,
                 checked: bool = False) -> Optional[Outcome]:
        """Start (or replace) the goal; returns an ABORTED outcome if the goal is refused.

        Args:
            x, y, z: goal position in the global frame [m].
            q: goal orientation (x, y, z, w).
            now: current time [s].
            checked: the backend's reachability check was passed already (a goal taken over from the instance
                that accepted it): not repeated. It reads the global costmap, so it waits for an update in
                progress: on the capped robot up to hundreds of ms before a taken-over goal's first command.
        """
        problem = goal_problem(x, y, z, q)
        if problem is not None:
            text, detail = problem
            log.warning('%s: %s', text, detail)
            self.reset()
            return Outcome('ABORTED', text)
        goal = Pose2D(float(x), float(y), quaternion_to_yaw(q))
        try:
            if not checked:
                self.backend.check_goal(goal)
        except PlanningError as err:
            text = f'Aborting on goal because it cannot be reached: {err.text}'
            log.warning(text)
            self.reset()
            return Outcome('ABORTED', text)
        with self.lock:
            self._epoch += 1
            self._reset_state()
            self.goal = goal
            self.plan = None
            self.run_planner_flag = True
            self.t = _Timers(last_valid_plan=now, last_valid_control=now, last_oscillation_reset=now)
        return None

    # -- migration (the goal continues in another instance; core/migration.py) ------------------------
    def recovery_state(self) -> Tuple[int, str]:
        """(next recovery index, trigger name): where the recovery sequence of the current goal stands."""
        with self.lock:
            return self.recovery_index, self.recovery_trigger.name

    def restore_recovery(self, index: int, trigger: str) -> None:
        """Continue the recovery sequence of a goal taken over from another instance (call after
        :meth:`new_goal`). ValueError if ``index`` is beyond this instance's recoveries or ``trigger`` unknown."""
        if not 0 <= index <= len(self.recoveries):
            raise ValueError(f'recovery_index {index} is outside 0..{len(self.recoveries)}')
        if trigger not in RecoveryTrigger.__members__:
            raise ValueError(f'unknown recovery trigger {trigger!r}')
        with self.lock:
            self.recovery_index = index
            self.recovery_trigger = RecoveryTrigger[trigger]

    def restore_plan(self, plan: np.ndarray, now: float) -> None:
        """Continue a goal taken over while it was being controlled (call after :meth:`new_goal`): control along
        the previous instance's global plan ((N, 3)) at once, as after a plan of its own; the planner replans
        ``1 / planner_frequency`` s later (or never, at 0), as it would have."""
        plan = np.asarray(plan, dtype=np.float64).reshape(-1, 3)
        with self.lock:
            if self.goal is None or plan.shape[0] == 0:
                return
            self.plan = plan
            self.new_global_plan = True
            self.state = NavState.CONTROLLING
            self.t.last_valid_plan = now
            if self.cfg.planner_frequency > 0:
                self.t.next_plan_time = now + 1.0 / self.cfg.planner_frequency
            else:
                self.run_planner_flag = False

    def controlled_plan(self) -> Optional[np.ndarray]:
        """The global plan the goal is being controlled along (None if it is not being controlled). Without the
        lock (a freeze must not wait for a control cycle): ``state`` and ``plan`` are each replaced whole, never
        changed in place."""
        state, plan = self.state, self.plan
        return None if state != NavState.CONTROLLING or plan is None else plan.copy()

    def resume(self, now: float) -> None:
        """The control loop was paused (outputs closed while the lease lapsed) and runs again at ``now`` [s]:
        the patience and oscillation timers restart, so the pause itself triggers no recovery."""
        with self.lock:
            if self.goal is None:
                return
            self.t.last_valid_plan = self.t.last_valid_control = self.t.last_oscillation_reset = now
            self.oscillation_pose = None
            if self.state == NavState.CONTROLLING:
                self.run_planner_flag = True        # the robot may have drifted: plan again from where it is

    # -- planner side (planThread) ----------------------------------------------------------------------
    def planner_due(self, now: float) -> bool:
        with self.lock:
            return self.goal is not None and self.run_planner_flag and now >= self.t.next_plan_time

    def run_planner(self, now: float, clock: Optional[Callable[[], float]] = None) -> bool:
        """Make one plan if one is due; returns True if a plan was attempted.

        Args:
            now: time the attempt starts [s].
            clock: reads the time after planning (the node's sim clock); default: ``now``.
        """
        with self.lock:
            if not (self.goal is not None and self.run_planner_flag and now >= self.t.next_plan_time):
                return False
            goal, epoch = self.goal, self._epoch
        start = self.backend.robot_pose()
        plan: Optional[np.ndarray] = None
        error = ''
        if start is None:
            error = 'Unable to get starting pose of robot, unable to create global plan'
        else:
            try:
                plan = self.backend.make_plan(start, goal)
            except PlanningError as err:
                error = err.text
        done = now if clock is None else clock()
        with self.lock:
            if epoch != self._epoch:          # the goal changed while planning
                return True
            if self.cfg.planner_frequency > 0:
                self.t.next_plan_time = now + 1.0 / self.cfg.planner_frequency
            else:
                self.t.next_plan_time = done
            if plan is not None and len(plan) > 0:
                self.plan = plan
                self.new_global_plan = True
                self.t.last_valid_plan = done
                self.planning_retries = 0
                if self.run_planner_flag:
                    self.state = NavState.CONTROLLING
                if self.cfg.planner_frequency <= 0:
                    self.run_planner_flag = False
            elif self.state == NavState.PLANNING:
                log.debug('No plan: %s', error)
                attempt_end = self.t.last_valid_plan + self.cfg.planner_patience
                self.planning_retries += 1
                if self.run_planner_flag and (done > attempt_end or (
                        self.cfg.max_planning_retries >= 0 and self.planning_retries > self.cfg.max_planning_retries)):
                    log.warning('Failed to get a plan to (%.2f, %.2f) for %.1f s: %s',
                                goal.x, goal.y, done - self.t.last_valid_plan, error)
                    self.state = NavState.CLEARING
                    self.run_planner_flag = False
                    self.recovery_trigger = RecoveryTrigger.PLANNING_R
            else:
                log.debug('Replanning failed (keeping the previous plan): %s', error)
        return True

    # -- controller side (executeCycle) ------------------------------------------------------------------
    def cycle(self, now: float) -> CycleResult:
        """One control cycle at ``now`` [s]; see ``MoveBase::executeCycle``."""
        if self.goal is None:
            return CycleResult(None)
        if self.sync_planner:
            self.run_planner(now)
        with self.lock:
            return self._cycle(now)

    def _cycle(self, now: float) -> CycleResult:
        cfg = self.cfg
        pose = self.backend.robot_pose()
        if pose is None:
            log.warning('Could not get the robot pose; stopping the base.')
            return CycleResult(ZERO)
        if self.oscillation_pose is None or pose.distance(self.oscillation_pose) >= cfg.oscillation_distance:
            self.t.last_oscillation_reset = now
            self.oscillation_pose = pose
            if self.recovery_trigger == RecoveryTrigger.OSCILLATION_R:
                self.recovery_index = 0
        if not self.backend.sensors_current():
            log.warning("Sensor data is out of date, we're not going to allow commanding of the base for safety")
            return CycleResult(ZERO, pose=pose)
        if self.new_global_plan:
            self.new_global_plan = False
            assert self.plan is not None
            if not self.backend.set_plan(self.plan):
                log.error('Failed to pass global plan to the controller, aborting.')
                return self._finish(Outcome('ABORTED', TEXT_PASS_PLAN), pose)
            if self.recovery_trigger == RecoveryTrigger.PLANNING_R:
                self.recovery_index = 0

        if self.state == NavState.PLANNING:
            self.run_planner_flag = True
            return CycleResult(None, pose=pose)

        if self.state == NavState.CONTROLLING:
            if self.backend.is_goal_reached():
                return self._finish(Outcome('SUCCEEDED', TEXT_GOAL_REACHED), pose)
            if cfg.oscillation_timeout > 0.0 and self.t.last_oscillation_reset + cfg.oscillation_timeout < now:
                self.state = NavState.CLEARING
                self.recovery_trigger = RecoveryTrigger.OSCILLATION_R
                return CycleResult(ZERO, pose=pose)
            cmd = self.backend.compute_velocity()
            if cmd is not None:
                self.t.last_valid_control = now
                if self.recovery_trigger == RecoveryTrigger.CONTROLLING_R:
                    self.recovery_index = 0
                return CycleResult(cmd, pose=pose)
            if now > self.t.last_valid_control + cfg.controller_patience:
                self.state = NavState.CLEARING
                self.recovery_trigger = RecoveryTrigger.CONTROLLING_R
            else:
                # move_base: no valid control yet -> replan, keep the patience timer running
                self.t.last_valid_plan = now
                self.planning_retries = 0
                self.state = NavState.PLANNING
                self.run_planner_flag = True
            return CycleResult(ZERO, pose=pose)

        # CLEARING
        started = None
        if self.active_recovery is None:
            if cfg.recovery_behavior_enabled and self.recovery_index < len(self.recoveries):
                self.active_recovery = self.recoveries[self.recovery_index]
                log.info('Executing behavior %d of %d: %s', self.recovery_index + 1, len(self.recoveries),
                         self.active_recovery.name)
                self.active_recovery.start(now)
                started = (self.recovery_index, len(self.recoveries), self.active_recovery.name)
            else:
                return self._abort_after_recoveries(pose)
        step = self.active_recovery.step(now)
        if step.message:
            log.info(step.message)
        if step.done:
            self.active_recovery = None
            self.t.last_oscillation_reset = now
            self.t.last_valid_plan = now
            self.planning_retries = 0
            self.state = NavState.PLANNING
            self.recovery_index += 1
        return CycleResult(step.cmd, recovery=started, pose=pose)

    def _abort_after_recoveries(self, pose: Pose2D) -> CycleResult:
        self.run_planner_flag = False
        if self.recovery_trigger == RecoveryTrigger.CONTROLLING_R:
            log.error('Aborting because a valid control could not be found. Even after executing all recovery behaviors')
            text = TEXT_NO_CONTROL
        elif self.recovery_trigger == RecoveryTrigger.PLANNING_R:
            log.error('Aborting because a valid plan could not be found. Even after executing all recovery behaviors')
            text = TEXT_NO_PLAN
        else:
            log.error('Aborting because the robot appears to be oscillating over and over. '
                      'Even after executing all recovery behaviors')
            text = TEXT_OSCILLATING
        return self._finish(Outcome('ABORTED', text), pose)

    def _finish(self, outcome: Outcome, pose: Optional[Pose2D]) -> CycleResult:
        self._epoch += 1
        self.goal = None
        self.plan = None
        self._reset_state()
        return CycleResult(ZERO, outcome=outcome, pose=pose)


@dataclass
class RecoverySpec:
    """An entry of ``~recovery_behaviors``: ``name`` and plugin ``type``."""

    name: str
    type: str


def default_recovery_specs(clearing_rotation_allowed: bool) -> List[RecoverySpec]:
    """move_base's ``loadDefaultRecoveryBehaviors``: conservative clear, rotate, aggressive clear, rotate."""
    specs = [RecoverySpec('conservative_reset', 'clear_costmap_recovery/ClearCostmapRecovery')]
    if clearing_rotation_allowed:
        specs.append(RecoverySpec('rotate_recovery', 'rotate_recovery/RotateRecovery'))
    specs.append(RecoverySpec('aggressive_reset', 'clear_costmap_recovery/ClearCostmapRecovery'))
    if clearing_rotation_allowed:
        specs.append(RecoverySpec('rotate_recovery', 'rotate_recovery/RotateRecovery'))
    return specs
