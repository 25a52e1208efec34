"""One task's network-aware decision from start to end (thesis §4.2.3-§4.2.6), without ROS.

The migration_decider node feeds a :class:`TaskAdvisor` with network profiles and task results; the advisor
holds one :class:`~network_monitor.core.decision.Decider` per ⟨task, location⟩ (trained on that set's rows,
retrained after each row appended) and, while a task runs, a :class:`~network_monitor.core.hysteresis.ReDecider`::

    begin(task, location, profile, now, force)  -> Decision and the placement to make (before the task)
    placed(now, moved, hosts)                   -> the initial migrations count in the re-decision's budget;
                                                   where the modules really are (a migration may be refused)
    observe(profile, now)                       -> a new placement to migrate to mid-task, or None (with the
                                                   modules on the cloud, R_bw as if they were home: r_bw_at_home)
    switched(hosts)                             -> where the modules are after that migration
    finish(status, t_task, b_task, timestamp)   -> the evaluated Row (Eq. 4-5, label), appended when asked

A *forced* placement (control runs, the second run of a paired condition) is run and evaluated like a decision
(``reason`` ``forced``); it is marked ``explored`` when it differs from what the policy would have chosen, as an
exploration is. Forced and explored placements are not re-decided during the task. The row records the placement at the start and each mid-task change (``move_base=cloud>robot``).

A task is evaluated as what ran: when a migration was refused or rolled back and every module stayed on the
other host, the row's decision is that other placement (and ``explored`` if the policy wanted otherwise); when
the modules ended split between the hosts, the run is evaluated but not learned (no placement to label).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

from network_monitor.core.decision import EXPLORE, NO_PROFILE, Decider, Decision
from network_monitor.core.decision_config import DecisionConfig
from network_monitor.core.evaluation import (DECISIONS, OFFLOAD, ONLOAD, ControlValues, evaluate,
                                             load_control_values)
from network_monitor.core.hysteresis import ReDecider
from network_monitor.core.training import LOCAL, Row

FORCED = 'forced'
SPLIT = 'split'             # the running placement when the task's modules are on both hosts
REDECISION = 'redecision'


@dataclass(frozen=True)
class Profile:
    """What the decision needs of a network profile (cnr_msgs/NetworkProfile)."""
    c_l: float              # RTT [s], NaN if unknown
    r_bw: float             # A_bw / C_bw, NaN if unknown
    rtt_spread: float       # s, NaN if unknown
    loss: float             # 0..1, NaN if unknown
    method: str             # probe | passive | none
    alive: bool = True
    a_bw: float = math.nan  # bit/s, NaN if unknown (R_bw's numerator)
    c_bw: float = math.nan  # bit/s, NaN if unknown (the link's use, R_bw's denominator above its floor)

    @property
    def usable(self) -> bool:
        return self.alive and not (math.isnan(self.c_l) or math.isnan(self.r_bw))


def r_bw_at_home(now: Profile, home: Profile) -> float:
    """R_bw of a profile taken with the task's modules on the cloud, as if they were at home, where the decision's
    profile ``home`` was taken (``profile_at_home``) and the training rows were: their own streams (an offloaded
    move_base is sent every laser scan) are in ``now``'s C_bw and missing from its A_bw, so they are given back
    to A_bw, and the denominator is ``home``'s (its max(C_bw, floor)); ``now.r_bw`` when either lacks a value."""
    values = (now.a_bw, now.c_bw, home.a_bw, home.c_bw, home.r_bw)
    if not all(math.isfinite(v) for v in values) or home.r_bw <= 0 or home.a_bw <= 0:
        return now.r_bw
    own = max(0.0, now.c_bw - home.c_bw)
    return (now.a_bw + own) / (home.a_bw / home.r_bw)


@dataclass
class RunningTask:
    task: str
    location: str
    profile: Profile
    decision: Decision
    started: float                              # monotonic [s]
    placement: str                              # offload | onload now
    history: List[Dict[str, str]] = field(default_factory=list)   # module -> host in order (start, each switch)
    redecider: Optional[ReDecider] = None


class AdvisorError(ValueError):
    """A request the advisor refuses (unknown task or location, a task already running, none running)."""


class TaskAdvisor:
    """Decisions, re-decisions and evaluations of one robot's tasks (module docstring).

    Args:
        cfg: the decision configuration (config/decision.yaml).
        rng: the exploration's random source (default: seeded from the configuration).
    """

    def __init__(self, cfg: DecisionConfig, rng: Optional[random.Random] = None) -> None:
        self.cfg = cfg
        self.rng = rng if rng is not None else random.Random(cfg.decision.exploration.seed)
        self._deciders: Dict[Tuple[str, str], Decider] = {}
        self.running: Optional[RunningTask] = None
        self.learned = False        # whether the last finished task's row was appended to its training set

    # ---------------------------------------------------------------- training sets
    def decider(self, task: str, location: str) -> Tuple[Decider, List[str]]:
        """The ⟨task, location⟩'s decider, trained on its set as it is on disk now; and the set's warnings
        (corrupt lines skipped)."""
        rows, warnings = self.cfg.training_set(task, location).read()
        key = (task, location)
        if key not in self._deciders:
            self._deciders[key] = Decider(self.cfg.decision, rows, rng=self.rng)
        else:
            self._deciders[key].retrain(rows)
        return self._deciders[key], warnings

    def control(self, task: str) -> ControlValues:
        """The task's control values (raises ConfigError naming the file if they have not been measured)."""
        return load_control_values(self.cfg.control_values, task)

    # ---------------------------------------------------------------- a task
    def begin(self, task: str, location: str, profile: Profile, now: float, force: str = '',
              explore: bool = True) -> \
            Tuple[Decision, Dict[str, str], List[str]]:
        """Decide before a task (``explore`` False: the policy, never an exploration). Returns the decision,
        the host each of the task's modules must be active on, and the training set's warnings."""
        if self.running is not None:
            raise AdvisorError(f'task {self.running.task}@{self.running.location} is still running (evaluate it '
                               f'first)')
        if task not in self.cfg.tasks:
            raise AdvisorError(f'unknown task {task!r} (configured: {", ".join(self.cfg.tasks)})')
        if location not in self.cfg.locations:
            raise AdvisorError(f'unknown location {location!r} (configured: {", ".join(self.cfg.locations)})')
        if force and force not in DECISIONS:
            raise AdvisorError(f'force must be offload, onload or empty, got {force!r}')
        decider, warnings = self.decider(task, location)
        c_l, r_bw = (profile.c_l, profile.r_bw) if profile.usable else (math.nan, math.nan)
        if force:
            policy = decider.policy(c_l, r_bw)
            d = Decision(force, FORCED, policy.decision, policy.votes, policy.neighbours, policy.point,
                         policy.votes.get(force, 0) / self.cfg.decision.k if policy.votes else 1.0)
        else:
            d = decider.decide(c_l, r_bw) if explore else decider.policy(c_l, r_bw)
        self.running = RunningTask(task, location, profile, d, now, d.decision, [self.hosts(task, d.decision)])
        return d, self.hosts(task, d.decision), warnings

    def hosts(self, task: str, decision: str) -> Dict[str, str]:
        """module -> host for ``decision`` of ``task``."""
        host = self.cfg.cloud_host if decision != ONLOAD else self.cfg.robot_host
        return {m: host for m in self.cfg.tasks[task]}

    def placement_of(self, task: str, hosts: Dict[str, str]) -> Optional[str]:
        """offload or onload when ``hosts`` is one of the two placements of ``task``, None when split."""
        for decision in DECISIONS:
            if hosts == self.hosts(task, decision):
                return decision
        return None

    def placed(self, now: float, moved: int, hosts: Optional[Dict[str, str]] = None) -> None:
        """The placement before the task is made (``moved`` migrations), the modules active on ``hosts``
        (None: as decided); re-deciding starts now, unless the placement was forced or explored: that one is
        held for the whole task, so that its outcome measures it (a paired run's oracle, an exploration's
        lesson)."""
        r = self._need_running()
        if hosts is not None:
            self._ran(r, hosts)
        if r.decision.reason in (FORCED, EXPLORE) or r.placement not in DECISIONS:    # split: not re-decided
            return
        r.redecider = ReDecider(self.cfg.redecision, r.placement)
        for _ in range(moved):
            r.redecider.migrated(now)

    def observe(self, profile: Profile, now: float) -> Optional[Tuple[str, Decision]]:
        """A profile during the task: the new placement (and the k-NN's view) if the modules should migrate
        now (hysteresis and budget, :class:`ReDecider`), else None. An unusable profile (peer lost, no RTT)
        wants the robot with full confidence."""
        r = self.running
        if r is None or r.redecider is None:
            return None
        decider = self._deciders[(r.task, r.location)]
        c_l, r_bw = (profile.c_l, profile.r_bw) if profile.usable else (math.nan, math.nan)
        if profile.usable and r.placement == OFFLOAD:
            r_bw = r_bw_at_home(profile, r.profile)     # comparable with the decision's and the rows' profiles
        d = decider.policy(c_l, r_bw)
        switch = r.redecider.update(now, d.decision, 1.0 if d.reason == NO_PROFILE else d.confidence)
        if switch is None:
            return None
        r.placement = switch
        r.history.append(self.hosts(r.task, switch))
        return switch, d

    def switched(self, hosts: Dict[str, str]) -> None:
        """Where the modules are after a mid-task migration (:meth:`observe`'s): a refused or rolled-back one
        leaves them where they were."""
        r = self.running
        if r is not None:
            self._ran(r, hosts)
            if r.redecider is not None and r.placement in DECISIONS:
                r.redecider.placement = r.placement

    def _ran(self, r: RunningTask, hosts: Dict[str, str]) -> None:
        r.history[-1] = {m: hosts.get(m, '') for m in self.cfg.tasks[r.task]}
        ran = self.placement_of(r.task, r.history[-1])
        r.placement = ran if ran is not None else SPLIT

    def finish(self, mission_status: str, t_task: float, b_task: float, timestamp: float,
               learn: bool) -> Tuple[Row, ControlValues]:
        """Evaluate the running task (Eq. 4-5) and end it; append its row to the training set if ``learn``.

        Raises:
            AdvisorError: no task is running.
            ConfigError: the task has no control values (the task stays running: measure them and retry).
            ValueError: a bad status or a non-finite time or battery.
        """
        r = self._need_running()
        control = self.control(r.task)
        ran = self.placement_of(r.task, r.history[0])          # what the task started with
        decision = ran if ran is not None else r.decision.decision
        ev = evaluate(decision, mission_status, t_task, b_task, control, self.cfg.v_r)
        placement = ','.join(f'{m}=' + '>'.join(_dedup([h[m] or '?' for h in r.history]))
                             for m in self.cfg.tasks[r.task])
        p = r.profile
        row = Row(r_bw=p.r_bw if p.usable else math.nan, c_l=p.c_l if p.usable else math.nan,
                  decision=decision, mission_status=mission_status, b_task=float(b_task),
                  t_task=float(t_task), timestamp=float(timestamp), task=r.task, location=r.location,
                  placement=placement, rtt_spread=p.rtt_spread, loss=p.loss,
                  profile_method=p.method if p.method in ('probe', 'passive') else 'passive',
                  value=ev.value, good=ev.good, label=ev.label,
                  explored=decision != r.decision.policy, source=LOCAL)
        self.learned = bool(learn and p.usable and ran is not None)
        if self.learned:
            self.cfg.training_set(r.task, r.location).append(row)
        self.running = None
        return row, control

    def abandon(self) -> None:
        """Forget the running task without evaluating it (e.g. its runner went away)."""
        self.running = None

    def _need_running(self) -> RunningTask:
        if self.running is None:
            raise AdvisorError('no task is running (call decide first)')
        return self.running


def _dedup(seq: List[str]) -> List[str]:
    """Consecutive duplicates removed: [cloud, cloud, robot] -> [cloud, robot]."""
    out: List[str] = []
    for s in seq:
        if not out or out[-1] != s:
            out.append(s)
    return out
