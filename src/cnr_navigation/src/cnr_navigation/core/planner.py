"""Global planner over a costmap with scikit-image's MCP (Dijkstra on the grid), in navfn's manner.

Traversal weights follow navfn (``navfn_ros.cpp`` / ``navfn.cpp``, ``setCostmap``): a cell of cost
c < 253 costs ``COST_NEUTRAL + COST_FACTOR * c`` = 50 + 0.8 c (normalised here by 50 so a free
cell weighs 1 per cell length); INSCRIBED (253) and LETHAL (254) cells are not traversable;
unknown cells are traversable at the highest weight only with ``allow_unknown``.
``skimage.graph.MCP_Geometric`` weighs diagonal moves by sqrt(2), so the cumulative cost is a
cost-weighted path length in cells.

Unknown space: with ``track_unknown_space`` false (TurtleBot) the costmap holds no unknown cells,
so the planner also takes the static map's unknown mask (:attr:`PlanningGrid.unknown`): with
``allow_unknown`` false those cells are not traversable and a goal there is refused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from skimage.graph import MCP_Geometric

from cnr_navigation.core.costmap import (INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION,
                                         GridGeometry)
from cnr_navigation.core.geometry import Pose2D

COST_NEUTRAL = 50.0
COST_FACTOR = 0.8


class PlanningError(Exception):
    """No plan. ``reason`` is one of: start_off_map, goal_off_map, goal_in_obstacle, goal_in_unknown,
    invalid_goal, no_path; ``str(err)`` is the log/status text."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason
        self.text = text


@dataclass
class PlannerConfig:
    """``~NavfnROS/*``.

    Attributes:
        allow_unknown: plan through unknown cells (and accept goals there).
        default_tolerance: if the goal cell is unreachable, accept the reachable cell closest to it
            within this distance [m] (navfn's ``default_tolerance``).
        visualize_potential: accepted for compatibility (no potential field is published).
        planner_window_x / planner_window_y: accepted for compatibility (the whole costmap is used).
    """

    allow_unknown: bool
    default_tolerance: float
    visualize_potential: bool
    planner_window_x: float
    planner_window_y: float


@dataclass
class PlanningGrid:
    """What the planner needs from a costmap: costs (uint8), their geometry, optional unknown mask."""

    costs: np.ndarray
    geometry: GridGeometry
    unknown: Optional[np.ndarray] = None
    inscribed_radius: float = 0.0


def traversal_weights(costs: np.ndarray, allow_unknown: bool, unknown: Optional[np.ndarray] = None) -> np.ndarray:
    """navfn's cell weights (float64, +inf where not traversable), normalised so free = 1."""
    c = costs.astype(np.float64)
    w = np.minimum(COST_NEUTRAL + COST_FACTOR * c, 253.0) / COST_NEUTRAL
    w[costs >= INSCRIBED_INFLATED_OBSTACLE] = np.inf
    unknown_cells = costs == NO_INFORMATION
    if unknown is not None:
        unknown_cells = unknown_cells | unknown
    w[unknown_cells] = 253.0 / COST_NEUTRAL if allow_unknown else np.inf
    w[costs == LETHAL_OBSTACLE] = np.inf
    return w


class GlobalPlanner:
    """Plans on a :class:`PlanningGrid`; see :meth:`make_plan`."""

    def __init__(self, cfg: PlannerConfig) -> None:
        self.cfg = cfg

    def check_goal(self, grid: PlanningGrid, goal: Pose2D, tolerance: Optional[float] = None) -> None:
        """Raise :class:`PlanningError` if no plan can ever reach ``goal`` in ``grid``.

        Used with the static costmap (no sensor marks) to refuse a goal at once. With a positive
        tolerance [m] (default ``default_tolerance``) only the off-map check applies.
        """
        if not goal.is_finite():
            raise PlanningError('invalid_goal', 'The goal contains NaN or infinite coordinates.')
        g = grid.geometry
        row, col = g.world_to_cell(goal.x, goal.y)
        if not g.inside(row, col):
            x1, y1 = g.origin_x + g.size_m[0], g.origin_y + g.size_m[1]
            raise PlanningError(
                'goal_off_map',
                f'The goal ({goal.x:.2f}, {goal.y:.2f}) is off the global costmap '
                f'([{g.origin_x:.2f}, {x1:.2f}] x [{g.origin_y:.2f}, {y1:.2f}] m). Planning will always fail '
                'to this goal.')
        if (self.cfg.default_tolerance if tolerance is None else tolerance) > 0.0:
            return
        cost = int(grid.costs[row, col])
        if cost in (LETHAL_OBSTACLE, INSCRIBED_INFLATED_OBSTACLE):
            kind = 'an obstacle' if cost == LETHAL_OBSTACLE else 'the inscribed radius of an obstacle'
            raise PlanningError(
                'goal_in_obstacle',
                f'The goal ({goal.x:.2f}, {goal.y:.2f}) is in {kind} (cost {cost}). Planning will always '
                'fail to this goal.')
        if not self.cfg.allow_unknown and (cost == NO_INFORMATION or
                                           (grid.unknown is not None and bool(grid.unknown[row, col]))):
            raise PlanningError(
                'goal_in_unknown',
                f'The goal ({goal.x:.2f}, {goal.y:.2f}) is in unknown space and allow_unknown is false. '
                'Planning will always fail to this goal.')

    def make_plan(self, grid: PlanningGrid, start: Pose2D, goal: Pose2D,
                  tolerance: Optional[float] = None) -> np.ndarray:
        """A collision-free path from ``start`` to ``goal``.

        Args:
            grid: costmap to plan on.
            start / goal: poses in the costmap frame.
            tolerance: overrides ``default_tolerance`` [m] (as GetPlan's ``tolerance``).

        Returns:
            (N, 3) float array of (x, y, yaw) poses: the start, cell centres, and the goal (or the
            reachable cell nearest to it within tolerance) with the goal's yaw; intermediate yaws
            point along the path.

        Raises:
            PlanningError: start or goal off the costmap, goal in an obstacle or unknown space, or
                no path (text ``Failed to get a plan.`` as move_base logs it).
        """
        g = grid.geometry
        if not start.is_finite():
            raise PlanningError('start_off_map', 'The robot pose contains NaN.')
        s_row, s_col = (int(v) for v in g.world_to_cell(start.x, start.y))
        if not g.inside(s_row, s_col):
            raise PlanningError(
                'start_off_map', "The robot's start position is off the global costmap. Planning will always "
                'fail, are you sure the robot has been properly localized?')
        tol = self.cfg.default_tolerance if tolerance is None else max(0.0, tolerance)
        self.check_goal(grid, goal, tol)
        weights = traversal_weights(grid.costs, self.cfg.allow_unknown, grid.unknown)
        # navfn clears the robot's own cell; also let the robot leave the inscribed zone it may sit in
        r_cells = int(math.ceil(grid.inscribed_radius / g.resolution))
        r0, r1 = max(0, s_row - r_cells), min(g.height, s_row + r_cells + 1)
        c0, c1 = max(0, s_col - r_cells), min(g.width, s_col + r_cells + 1)
        near = weights[r0:r1, c0:c1]
        escape = grid.costs[r0:r1, c0:c1] == INSCRIBED_INFLATED_OBSTACLE
        near[escape] = 253.0 / COST_NEUTRAL
        weights[s_row, s_col] = 1.0
        g_row, g_col = (int(v) for v in g.world_to_cell(goal.x, goal.y))
        ends = self._goal_cells(weights, g, goal, g_row, g_col, tol)
        if not ends:
            raise PlanningError('no_path', 'Failed to get a plan.')
        mcp = MCP_Geometric(weights, fully_connected=True)
        cumulative, _ = mcp.find_costs([(s_row, s_col)], ends, find_all_ends=True)
        reached = [e for e in ends if np.isfinite(cumulative[e])]
        if not reached:
            raise PlanningError('no_path', 'Failed to get a plan.')
        ex, ey = g.cell_to_world(np.array([e[0] for e in reached]), np.array([e[1] for e in reached]))
        best = int(np.argmin(np.hypot(ex - goal.x, ey - goal.y)))
        end = reached[best]
        cells = np.asarray(mcp.traceback(end), dtype=np.int64)
        xs, ys = g.cell_to_world(cells[:, 0], cells[:, 1])
        xs[0], ys[0] = start.x, start.y
        if end == (g_row, g_col):
            xs[-1], ys[-1] = goal.x, goal.y
        return path_with_headings(np.asarray(xs, dtype=np.float64), np.asarray(ys, dtype=np.float64), goal.yaw)

    @staticmethod
    def _goal_cells(weights: np.ndarray, g: GridGeometry, goal: Pose2D, g_row: int, g_col: int, tol: float):
        if np.isfinite(weights[g_row, g_col]) or tol <= 0.0:
            return [(g_row, g_col)] if np.isfinite(weights[g_row, g_col]) else []
        r = int(math.ceil(tol / g.resolution))
        rows, cols = np.mgrid[g_row - r:g_row + r + 1, g_col - r:g_col + r + 1]
        xs, ys = g.cell_to_world(rows, cols)
        sel = g.inside(rows, cols) & (np.hypot(xs - goal.x, ys - goal.y) <= tol)
        sel[sel] &= np.isfinite(weights[rows[sel], cols[sel]])
        return list(zip(rows[sel].tolist(), cols[sel].tolist()))


def path_with_headings(xs: np.ndarray, ys: np.ndarray, final_yaw: float) -> np.ndarray:
    """(N, 3) poses whose yaw points to the next point; the last takes ``final_yaw``."""
    yaw = np.empty_like(xs)
    if xs.size > 1:
        yaw[:-1] = np.arctan2(np.diff(ys), np.diff(xs))
    yaw[-1] = final_yaw
    return np.column_stack((xs, ys, yaw))


def path_length(path: np.ndarray) -> float:
    """Length [m] of an (N, >=2) path."""
    if len(path) < 2:
        return 0.0
    return float(np.hypot(np.diff(path[:, 0]), np.diff(path[:, 1])).sum())
