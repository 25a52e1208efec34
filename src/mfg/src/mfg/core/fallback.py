"""The robot's own global goals while the global goal manager (possibly on the cloud) cannot be reached.

ROS-free. The robot never waits on the cloud: when ``next_goal`` does not answer, mfg keeps patrolling with the
global goal manager's own least-recently-visited policy (thesis §4.1.4), run on what the robot itself knows —
the time it last measured in each cell.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

from cnr_maps.grid import MapcellGrid
from global_goal_manager.core.policies import CellView, LeastRecentlyVisited
from mfg.core import statecheck
from mfg.core.statecheck import state_section


class LocalGoals:
    """Least recently visited cell from the robot's own measurement times."""

    name = 'least_recently_visited (local fallback)'

    def __init__(self) -> None:
        self._policy = LeastRecentlyVisited()
        self.last_visit: Dict[int, float] = {}

    def visited(self, cell: int, t: float) -> None:
        """Record a measurement in ``cell`` at time ``t`` [s]."""
        if t > self.last_visit.get(cell, 0.0):
            self.last_visit[cell] = t

    def next_cell(self, grid: MapcellGrid, robot_xy: Tuple[float, float]) -> Optional[int]:
        views = [CellView(c.index, c.row, c.col, c.center_x, c.center_y, self.last_visit.get(c.index, 0.0))
                 for c in grid.cells()]
        return self._policy.next_cell(views, grid.index_of(*robot_xy), robot_xy)

    # -- migration state (the package README, "Migration state") -----------------------------------------
    def state(self) -> Dict[str, Any]:
        """The visit times: ``{'last_visit': [[cell, t], ...]}`` (t: the last measurement's stamp there [s])."""
        return {'last_visit': [[c, t] for c, t in sorted(self.last_visit.items())]}

    def restore(self, state: Dict[str, Any], cells: Optional[int] = None, field: str = 'local_goals') -> None:
        """Take over :meth:`state` of another instance (ValueError naming ``field.key`` if it does not fit)."""
        sec = state_section(state, field)
        visits = {}
        for c, t in statecheck.rows(sec, 'last_visit', 2):
            visits[statecheck.check_cell(sec, 'last_visit', c, cells)] = statecheck.number(sec, 'last_visit', t)
        self.last_visit = visits
