"""What mfg knows and has decided: the node's state, the one an instance hands over in a migration (ROS-free).

The node feeds every stored measurement to :meth:`Memory.observe` (a managed standby too, so that a hot standby is
warm) and records its decisions here (mode, trigger, search, current goal). :meth:`Memory.to_state` is the
node's migration state (the keys are in the package README, "Migration state"); :meth:`Memory.restore` takes over
another instance's state: everything is checked first (ValueError naming the field, nothing changed), then the
measurements this instance received after the state's newest one (buffered while it was a standby) are replayed
through the restored detector, so nothing that arrived during the hand-over is lost.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Any, Deque, Dict, List, Optional, Tuple

from cnr_maps.grid import MapcellGrid
from mfg.core import statecheck
from mfg.core.activity import ActivityTracker
from mfg.core.detector import Detector, DetectorConfig
from mfg.core.fallback import LocalGoals
from mfg.core.search import HotspotSearch
from mfg.core.statecheck import state_section

MODES = ('IDLE', 'PATROL', 'SEARCH', 'DONE')      # IDLE: never active yet (a standby)
GOAL_KINDS = ('patrol', 'approach', 'check')      # a global goal; the trigger cell; an unchecked direction
MEASUREMENTS_KEPT = 5000                          # in memory (the search averages from these)
MEASUREMENTS_HANDED_OVER = 500                    # the newest ones, in the state (~170 s at 3 Hz)
TRAIL_KEPT = 100                                  # distinct cells in visiting order (in memory and the state)

Measurement = Tuple[float, int, float]            # (stamp [s], cell, temperature [degC])


@dataclass(frozen=True)
class Trigger:
    """The abnormal value that started (or will start) a hotspot search."""
    t: float                       # its stamp [s]
    cell: int
    temperature: float             # degC
    previous: Optional[int]        # the cell visited before (a checked direction of the search), if any

    def to_dict(self) -> Dict[str, Any]:
        return {'t': self.t, 'cell': self.cell, 'temperature': self.temperature, 'previous': self.previous}

    @classmethod
    def from_dict(cls, data: Any, cells: Optional[int], field: str = 'trigger') -> 'Trigger':
        sec = state_section(data, field)
        return cls(sec.number('t'), statecheck.cell(sec, 'cell', cells), sec.number('temperature'),
                   statecheck.cell(sec, 'previous', cells, optional=True))


@dataclass(frozen=True)
class Goal:
    """The move_base goal being driven to (re-sent unchanged by an instance that takes over)."""
    x: float                       # m, frame ``~mfg/frame_id``
    y: float                       # m
    yaw: float                     # rad
    cell: int                      # the cell whose centre it is
    interruptible: bool            # an abnormal value ends it (patrol goals)
    kind: str                      # GOAL_KINDS
    sent: float                    # when it was first sent [s, node clock]: the goal timeout counts from here

    def to_dict(self) -> Dict[str, Any]:
        return {'x': self.x, 'y': self.y, 'yaw': self.yaw, 'cell': self.cell, 'interruptible': self.interruptible,
                'kind': self.kind, 'sent': self.sent}

    @classmethod
    def from_dict(cls, data: Any, cells: Optional[int], field: str = 'goal') -> 'Goal':
        sec = state_section(data, field)
        return cls(sec.number('x'), sec.number('y'), sec.number('yaw'), statecheck.cell(sec, 'cell', cells),
                   sec.boolean('interruptible'), sec.string('kind', choices=GOAL_KINDS), sec.number('sent'))


def grid_to_dict(grid: MapcellGrid) -> Dict[str, Any]:
    return {'min_x': grid.min_x, 'min_y': grid.min_y, 'cell_size': grid.cell_size, 'cols': grid.cols,
            'rows': grid.rows}


class Memory:
    """mfg's state. Not thread-safe: the node holds its lock around every call and every access.

    Args:
        detector: the abnormal-value threshold (this instance's configuration).
        neighbourhood: 4 or 8 (the search's directions).
        suppress_radius: cells around a found hotspot whose values no longer trigger a search.
    """

    def __init__(self, detector: DetectorConfig, neighbourhood: int, suppress_radius: int) -> None:
        self.detector_cfg = detector
        self.neighbourhood = neighbourhood
        self.suppress_radius = suppress_radius
        self.grid: Optional[MapcellGrid] = None
        self.detector = Detector(detector)
        self.local_goals = LocalGoals()
        self.activity = ActivityTracker()
        self.mode = 'IDLE'
        self.trigger: Optional[Trigger] = None
        self.hotspots: List[int] = []
        self.cell_trail: Deque[int] = deque(maxlen=TRAIL_KEPT)
        self.measurements: Deque[Measurement] = deque(maxlen=MEASUREMENTS_KEPT)
        self.search: Optional[HotspotSearch] = None
        self.goal: Optional[Goal] = None

    def neighbours(self, cell: int) -> List[int]:
        return self.grid.neighbours(cell, self.neighbourhood)

    # -- inputs ----------------------------------------------------------------------------------------
    def observe(self, t: float, cell: int, temperature: float) -> Optional[Trigger]:
        """A stored measurement (stamp [s], its cell inside the grid, a finite temperature [degC]).

        Updates the statistics, the visit times and the trail; an abnormal value while patrolling (not near a
        found hotspot, no search pending) becomes the trigger, which is returned.
        """
        self._keep((t, cell, temperature))
        self.local_goals.visited(cell, t)
        if not self.cell_trail or self.cell_trail[-1] != cell:
            self.cell_trail.append(cell)
        abnormal = self.detector.observe(temperature)
        suppressed = any(self.grid.chebyshev(cell, h) <= self.suppress_radius for h in self.hotspots)
        if abnormal and not suppressed and self.trigger is None and self.mode == 'PATROL':
            previous = next((c for c in reversed(self.cell_trail) if c != cell), None)
            self.trigger = Trigger(t, cell, temperature, previous)
            return self.trigger
        return None

    def _keep(self, m: Measurement) -> None:
        """Kept in stamp order (the state's invariant): a late one — a store recovered it from the merger after a
        failover and published it after newer ones — goes to its place, or is dropped if older than all kept."""
        ms = self.measurements
        if not ms or m[0] >= ms[-1][0]:
            ms.append(m)
            return
        i = bisect.bisect_right(ms, m[0], key=lambda x: x[0])
        if len(ms) == ms.maxlen:
            if i == 0:
                return
            ms.popleft()
            i -= 1
        ms.insert(i, m)

    def values(self, cell: int, since: float = float('-inf')) -> List[float]:
        """Temperatures measured in ``cell`` with a stamp >= ``since`` [s], oldest first."""
        return [v for t, c, v in self.measurements if c == cell and t >= since]

    # -- migration state ---------------------------------------------------------------------------------
    def to_state(self) -> Dict[str, Any]:
        """The node's migration state (JSON-able; keys in the package README, "Migration state")."""
        recent = list(self.measurements)[-MEASUREMENTS_HANDED_OVER:]
        return {
            'mode': self.mode,
            'grid': grid_to_dict(self.grid) if self.grid is not None else None,
            'trigger': self.trigger.to_dict() if self.trigger is not None else None,
            'hotspots': list(self.hotspots),
            'cell_trail': list(self.cell_trail),
            'measurements': [[t, c, v] for t, c, v in recent],
            'detector': self.detector.state(),
            'local_goals': self.local_goals.state(),
            'activity': self.activity.state(),
            'search': self.search.state() if self.search is not None else None,
            'goal': self.goal.to_dict() if self.goal is not None else None,
        }

    def restore(self, state: Dict[str, Any]) -> int:
        """Take over another instance's :meth:`to_state`; returns how many of this instance's own newer
        measurements were replayed on top of it.

        Raises:
            ValueError: a key is missing or does not fit (wrong type or value, cells outside the grid, another
                grid than this instance's); the message names the field, and nothing has changed.
        """
        sec = state_section(state, '')
        mode = sec.string('mode', choices=MODES)
        grid = self.grid
        if sec.raw('grid') is not None:
            g = sec.section('grid')
            theirs = MapcellGrid(g.number('min_x'), g.number('min_y'), g.number('cell_size', positive=True),
                                 g.integer('cols', minimum=1), g.integer('rows', minimum=1))
            if grid is not None and theirs != grid:
                raise sec.error('grid', f'{grid_to_dict(theirs)} differs from this instance\'s {grid_to_dict(grid)}')
            grid = theirs
        cells = len(grid) if grid is not None else None
        trigger = None if sec.raw('trigger') is None else Trigger.from_dict(sec.raw('trigger'), cells)
        hotspots = statecheck.cell_list(sec, 'hotspots', cells)
        trail = statecheck.cell_list(sec, 'cell_trail', cells)
        measurements: List[Measurement] = []
        for t, c, v in statecheck.rows(sec, 'measurements', 3):
            measurements.append((statecheck.number(sec, 'measurements', t),
                                 statecheck.check_cell(sec, 'measurements', c, cells),
                                 statecheck.number(sec, 'measurements', v)))
        if any(b[0] < a[0] for a, b in zip(measurements, measurements[1:])):
            raise sec.error('measurements', 'stamps must not decrease')
        detector = Detector(self.detector_cfg)
        detector.restore(sec.raw('detector'))
        local_goals = LocalGoals()
        local_goals.restore(sec.raw('local_goals'), cells)
        activity = ActivityTracker()
        activity.restore(sec.raw('activity'))
        search = None
        if sec.raw('search') is not None:
            if grid is None:
                raise sec.error('search', 'a search without a grid (the state has none, nor has this instance)')
            search = HotspotSearch.from_state(lambda i: grid.neighbours(i, self.neighbourhood), sec.raw('search'),
                                              cells)
            if trigger is None:
                raise sec.error('search', 'a search without a trigger')
        goal = None if sec.raw('goal') is None else Goal.from_dict(sec.raw('goal'), cells)
        if goal is not None and goal.kind != 'patrol' and trigger is None:
            raise sec.error('goal', f'a goal of kind {goal.kind} without a trigger')
        if goal is not None and goal.kind == 'check' and search is None:
            raise sec.error('goal', 'a goal of kind check without a search')
        # all checked: take it over, keep what this instance knows around it, replay what came after it
        own = list(self.measurements)
        first = measurements[0][0] if measurements else float('inf')
        last = measurements[-1][0] if measurements else float('-inf')
        newer = [m for m in own if m[0] > last]
        self.grid, self.mode, self.trigger, self.hotspots = grid, mode, trigger, hotspots
        self.cell_trail = deque(trail, maxlen=TRAIL_KEPT)
        self.measurements = deque([m for m in own if m[0] < first] + measurements, maxlen=MEASUREMENTS_KEPT)
        self.detector, self.local_goals, self.activity = detector, local_goals, activity
        self.search, self.goal = search, goal
        for t, c, v in newer:
            self.activity.input(t)
            self.observe(t, c, v)
        return len(newer)
