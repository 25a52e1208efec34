"""Global goal policies: which mapcell the robot should go to next (ROS-free).

A policy sees every cell as :class:`CellView` (index, row, col, centre, last visit time) and returns the
index of the next goal cell. ``least_recently_visited`` is the thesis's algorithm with the timestamp
method the thesis proposed (§4.1.4): the cell with the earliest last-visit time, never-visited cells
first; ties go to the cell farthest from the robot, then the lowest index (deterministic). The robot's
own cell is never chosen. ``coverage_sweep`` drives a boustrophedon over the grid (the paper's Z patrol).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence

from cnr_params import ConfigError, Section


@dataclass(frozen=True)
class CellView:
    index: int
    row: int
    col: int
    x: float
    y: float
    last_visit: float       # 0 = never visited


class GoalPolicy:
    """Interface: ``next_cell(cells, robot_cell, robot_xy)`` -> index (None if no cell can be chosen)."""

    name = 'policy'

    def next_cell(self, cells: Sequence[CellView], robot_cell: Optional[int], robot_xy) -> Optional[int]:
        raise NotImplementedError

    def state(self) -> Dict[str, Any]:
        """What the policy remembers beyond the cells' visit times (handed over in a migration)."""
        return {}

    def restore(self, state: Dict[str, Any]) -> None:
        """Take over :meth:`state` of another instance."""


class LeastRecentlyVisited(GoalPolicy):
    name = 'least_recently_visited'

    def next_cell(self, cells, robot_cell, robot_xy):
        candidates = [c for c in cells if c.index != robot_cell]
        if not candidates:
            return None
        rx, ry = robot_xy

        def key(c: CellView):
            return (c.last_visit, -round(math.hypot(c.x - rx, c.y - ry), 6), c.index)
        return min(candidates, key=key).index


class CoverageSweep(GoalPolicy):
    """Boustrophedon: along row 0 to its end, up, back along row 1, ... and again from the start.

    Only the turning cells are goals (the robot measures every cell it drives through), so a corridor of
    two rows gives the paper's Z-shaped patrol.
    """

    name = 'coverage_sweep'

    def __init__(self) -> None:
        self._i = -1

    def state(self) -> Dict[str, Any]:
        return {'waypoint_index': self._i}       # where the sweep is: the next goal continues it

    def restore(self, state: Dict[str, Any]) -> None:
        i = state.get('waypoint_index')
        if not isinstance(i, int) or isinstance(i, bool):
            raise ValueError(f'coverage_sweep state: waypoint_index must be an integer, got {i!r}')
        self._i = i

    @staticmethod
    def waypoints(rows: int, cols: int) -> List[int]:
        out = []
        for r in range(rows):
            ends = (0, cols - 1) if r % 2 == 0 else (cols - 1, 0)
            out += [r * cols + ends[0], r * cols + ends[1]]
        return out

    def next_cell(self, cells, robot_cell, robot_xy):
        if not cells:
            return None
        rows = max(c.row for c in cells) + 1
        cols = max(c.col for c in cells) + 1
        seq = self.waypoints(rows, cols)
        for _ in range(len(seq)):
            self._i = (self._i + 1) % len(seq)
            if seq[self._i] != robot_cell:
                return seq[self._i]
        return None


POLICIES: Dict[str, Callable[[], GoalPolicy]] = {
    LeastRecentlyVisited.name: LeastRecentlyVisited,
    CoverageSweep.name: CoverageSweep,
}


def make_policy(name: str, source: str, field: str) -> GoalPolicy:
    if name not in POLICIES:
        raise ConfigError(source, field, f"unknown policy '{name}' (expected one of: {', '.join(POLICIES)})")
    return POLICIES[name]()


@dataclass
class GoalManagerParams:
    policy: GoalPolicy
    frame_id: str


def read_params(p: Section) -> GoalManagerParams:
    """``global_goal_manager.policy`` (scenario file) and ``frame_id`` (config/global_goal_manager.yaml); no defaults."""
    sec = p.section('global_goal_manager')
    return GoalManagerParams(policy=make_policy(sec.string('policy'), p.source, sec.path('policy')),
                             frame_id=p.string('frame_id'))
