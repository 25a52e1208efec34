"""move_base's migration state (ROS-free): the client's goal that the next instance must continue.

The state is a JSON object (``migration_manager.core.state`` carries it), documented key by key in the package
README ("Migration state")::

    {"goal": GOAL or null,         # the goal being pursued (ACTIVE, or PREEMPTING: cancel requested)
     "next_goal": NEXT or null,    # a newer goal received but not accepted yet (PENDING, or RECALLING)
     "seen_goals": [str],          # goal ids the instances so far received (newest last): a goal the next
     "seen_cancels": [[str, int, int]]}   # instance parked that is not among them was sent in the gap; cancels
                                          # as [goal id or '', stamp secs, nsecs]

    GOAL = NEXT + {"recovery_index": int, "recovery_trigger": "PLANNING_R" | "CONTROLLING_R" | "OSCILLATION_R"}
    NEXT = {"id": str, "stamp_secs": int, "stamp_nsecs": int,     # the actionlib goal id, as the client made it
            "frame": str, "x": m, "y": m, "yaw": rad,              # the target
            "cancel_requested": bool}

The target of an accepted goal is the one the state machine pursues, already in the global frame (a goal sent
relative to the robot stays where it was when the first instance accepted it); a goal not started yet keeps the
client's frame. Costmaps, plans and timers are not part of the state: the next instance has its own costmaps
from the sensors, plans anew and starts its patience timers at the hand-over.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Tuple

from cnr_navigation.core.geometry import Quaternion, quaternion_problem, quaternion_to_yaw

RECOVERY_TRIGGERS = ('PLANNING_R', 'CONTROLLING_R', 'OSCILLATION_R')    # move_base's RecoveryTrigger names


@dataclass(frozen=True)
class GoalRecord:
    """One goal of the action server as it is handed over.

    Attributes:
        id: actionlib goal id (the client matches status arrays by it).
        stamp_secs, stamp_nsecs: the goal id's stamp (the server orders goals by it).
        frame: frame of the target ('' is refused).
        x, y: target position [m]; yaw: target heading [rad]. Not checked for finiteness: the next instance
            refuses a goal with NaN/infinite values exactly as move_base does (aborted with its text).
        cancel_requested: the client asked to cancel it (the next instance preempts it at once).
        recovery_index: the next recovery behaviour to run (0: the first).
        recovery_trigger: what the recovery sequence is recovering from (a RecoveryTrigger name).
        plan: the global plan ((x, y, yaw) per pose, in the global frame) the goal was being controlled along
            (empty: it was not being controlled, e.g. planning or recovering). The next instance controls along
            it at once instead of planning first; its planner replans at ``planner_frequency`` as after any plan.
    """

    id: str
    stamp_secs: int
    stamp_nsecs: int
    frame: str
    x: float
    y: float
    yaw: float
    cancel_requested: bool = False
    recovery_index: int = 0
    recovery_trigger: str = 'PLANNING_R'
    plan: Tuple[Tuple[float, float, float], ...] = ()

    def to_dict(self, with_recovery: bool) -> Dict[str, Any]:
        out: Dict[str, Any] = {'id': self.id, 'stamp_secs': self.stamp_secs, 'stamp_nsecs': self.stamp_nsecs,
                               'frame': self.frame, 'x': self.x, 'y': self.y, 'yaw': self.yaw,
                               'cancel_requested': self.cancel_requested}
        if with_recovery:
            out['recovery_index'] = self.recovery_index
            out['recovery_trigger'] = self.recovery_trigger
            out['plan'] = [list(p) for p in self.plan]
        return out


@dataclass(frozen=True)
class HandOver:
    """The whole state: the goal being pursued and a newer one waiting to be accepted (either may be None)."""

    goal: Optional[GoalRecord] = None
    next_goal: Optional[GoalRecord] = None
    seen_goals: Optional[Tuple[str, ...]] = ()          # None: not known (a state of an older instance)
    seen_cancels: Tuple[Tuple[str, int, int], ...] = ()

    def to_dict(self) -> Dict[str, Any]:
        return {'goal': self.goal.to_dict(True) if self.goal else None,
                'next_goal': self.next_goal.to_dict(False) if self.next_goal else None,
                'seen_goals': list(self.seen_goals or ()),
                'seen_cancels': [list(c) for c in self.seen_cancels]}

    @property
    def empty(self) -> bool:
        return self.goal is None and self.next_goal is None


def _int(d: Mapping[str, Any], key: str, where: str, low: int, high: Optional[int] = None) -> int:
    v = d.get(key)
    if not isinstance(v, int) or isinstance(v, bool):
        raise ValueError(f'move_base state: {where}.{key} must be an integer, got {v!r}')
    if v < low or (high is not None and v > high):
        raise ValueError(f'move_base state: {where}.{key} must be in {low}..{"" if high is None else high}, got {v}')
    return v


def _float(d: Mapping[str, Any], key: str, where: str) -> float:
    v = d.get(key)
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        raise ValueError(f'move_base state: {where}.{key} must be a number, got {v!r}')
    return float(v)


def _str(d: Mapping[str, Any], key: str, where: str) -> str:
    v = d.get(key)
    if not isinstance(v, str) or not v:
        raise ValueError(f'move_base state: {where}.{key} must be a non-empty string, got {v!r}')
    return v


def _bool(d: Mapping[str, Any], key: str, where: str) -> bool:
    v = d.get(key)
    if not isinstance(v, bool):
        raise ValueError(f'move_base state: {where}.{key} must be true or false, got {v!r}')
    return v


def _record(d: Any, where: str, with_recovery: bool, recoveries: int) -> Optional[GoalRecord]:
    if d is None:
        return None
    if not isinstance(d, dict):
        raise ValueError(f'move_base state: {where} must be an object or null, got {type(d).__name__}')
    index, trigger, plan = 0, 'PLANNING_R', ()
    if with_recovery:
        plan = _plan(d.get('plan', []), where)
        index = _int(d, 'recovery_index', where, 0, recoveries)
        trigger = d.get('recovery_trigger')
        if trigger not in RECOVERY_TRIGGERS:
            raise ValueError(f'move_base state: {where}.recovery_trigger must be one of '
                             f'{", ".join(RECOVERY_TRIGGERS)}, got {trigger!r}')
    return GoalRecord(id=_str(d, 'id', where), stamp_secs=_int(d, 'stamp_secs', where, 0, 2 ** 32 - 1),
                      stamp_nsecs=_int(d, 'stamp_nsecs', where, 0, 999_999_999), frame=_str(d, 'frame', where),
                      x=_float(d, 'x', where), y=_float(d, 'y', where), yaw=_float(d, 'yaw', where),
                      cancel_requested=_bool(d, 'cancel_requested', where), recovery_index=index,
                      recovery_trigger=trigger, plan=plan)


def _plan(v: Any, where: str) -> Tuple[Tuple[float, float, float], ...]:
    """A handed-over plan: a list of [x, y, yaw] of finite numbers (absent in a state of an older instance)."""
    if not isinstance(v, list):
        raise ValueError(f'move_base state: {where}.plan must be a list of [x, y, yaw], got {type(v).__name__}')
    out = []
    for i, p in enumerate(v):
        if (not isinstance(p, list) or len(p) != 3
                or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in p)):
            raise ValueError(f'move_base state: {where}.plan[{i}] must be [x, y, yaw] of finite numbers, got {p!r}')
        out.append((float(p[0]), float(p[1]), float(p[2])))
    return tuple(out)


def parse_state(state: Any, recoveries: int) -> HandOver:
    """Check a handed-over state; ValueError naming the field that does not fit.

    Args:
        state: the decoded JSON object.
        recoveries: how many recovery behaviours this instance has (``recovery_index`` may be at most that:
            equal means every recovery has run).
    """
    if not isinstance(state, dict):
        raise ValueError(f'move_base state: must be an object, got {type(state).__name__}')
    for key in ('goal', 'next_goal'):
        if key not in state:
            raise ValueError(f'move_base state: {key} is missing (null if there is none)')
    unknown = sorted(set(state) - {'goal', 'next_goal', 'seen_goals', 'seen_cancels'})
    if unknown:
        raise ValueError(f'move_base state: unknown key {unknown[0]!r}')
    goal = _record(state['goal'], 'goal', True, recoveries)
    next_goal = _record(state['next_goal'], 'next_goal', False, recoveries)
    if goal is not None and next_goal is not None and goal.id == next_goal.id:
        raise ValueError(f'move_base state: next_goal.id {next_goal.id!r} is the id of goal')
    seen_goals: Optional[Tuple[str, ...]] = None
    if 'seen_goals' in state:
        v = state['seen_goals']
        if not isinstance(v, list) or not all(isinstance(g, str) and g for g in v):
            raise ValueError(f'move_base state: seen_goals must be a list of goal ids, got {v!r}')
        seen_goals = tuple(v)
    return HandOver(goal, next_goal, seen_goals, _cancels(state.get('seen_cancels', [])))


def _cancels(v: Any) -> Tuple[Tuple[str, int, int], ...]:
    """``seen_cancels``: a list of [goal id or '', stamp secs, stamp nsecs]."""
    if not isinstance(v, list):
        raise ValueError(f'move_base state: seen_cancels must be a list, got {type(v).__name__}')
    out: List[Tuple[str, int, int]] = []
    for i, c in enumerate(v):
        if (not isinstance(c, list) or len(c) != 3 or not isinstance(c[0], str)
                or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in c[1:])):
            raise ValueError(f'move_base state: seen_cancels[{i}] must be [goal id, secs, nsecs], got {c!r}')
        out.append((c[0], c[1], c[2]))
    return tuple(out)


def target_yaw(q: Quaternion) -> float:
    """The heading [rad] of a goal orientation (x, y, z, w) for the state; NaN if move_base would refuse it
    (the next instance then refuses the goal with move_base's text, as the first one would have)."""
    if quaternion_problem(q) is not None:
        return math.nan
    return quaternion_to_yaw(q)
