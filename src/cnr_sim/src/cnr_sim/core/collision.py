"""Clearance field for collision checks: Euclidean distance transform of the map's obstacles.

ROS-free. Obstacles are occupied cells (>= ``occupied_value``) and unknown cells (-1), as Stage
treats every dark pixel of its floorplan as solid; everything outside the map is solid too.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from cnr_maps.mapio import OccupancyMap


def obstacle_mask(grid: OccupancyMap, occupied_value: int = 50, unknown_is_obstacle: bool = True) -> np.ndarray:
    """Bool array (row 0 at the bottom): True where the robot cannot be and the laser reflects."""
    data = grid.data.astype(np.int16)
    mask = data >= occupied_value
    if unknown_is_obstacle:
        mask |= data < 0
    return mask


class ClearanceField:
    """Distance from any point to the nearest obstacle [m], precomputed once per map.

    Args:
        grid: the map.
        obstacle: obstacle mask of the map (see :func:`obstacle_mask`).
    """

    def __init__(self, grid: OccupancyMap, obstacle: np.ndarray) -> None:
        self.grid = grid
        res = grid.resolution
        # distance between cell centres, minus half a cell: distance to the obstacle's boundary
        edt = ndimage.distance_transform_edt(~obstacle) * res
        self.field = np.maximum(edt - 0.5 * res, 0.0)
        self.field[obstacle] = 0.0

    def clearance(self, x: float, y: float) -> float:
        """Clearance at a point [m]; 0 outside the map or inside an obstacle."""
        g = self.grid
        col = int((x - g.origin[0]) // g.resolution)
        row = int((y - g.origin[1]) // g.resolution)
        if row < 0 or col < 0 or row >= g.height or col >= g.width:
            return 0.0
        return float(self.field[row, col])

    def collides(self, x: float, y: float, radius: float) -> bool:
        """Whether a disc of ``radius`` at (x, y) overlaps an obstacle."""
        return self.clearance(x, y) < radius
