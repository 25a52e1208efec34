"""The robot's own global goals while the global goal manager (possibly on the cloud) cannot be reached.

ROS-free. The robot never waits on the cloud: when ``next_goal`` does not answer, mfg keeps patrolling with the
global goal manager's own least-recently-visited policy (thesis §4.1.4), run on what the robot itself knows —
the time it last measured in each cell.
"""
from __future__ import annotations

from typing import Dict, Optional, Tuple

from cnr_maps.grid import MapcellGrid
from global_goal_manager.core.policies import CellView, LeastRecentlyVisited


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
