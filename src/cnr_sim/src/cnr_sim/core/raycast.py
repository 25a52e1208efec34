"""Exact grid ray casting (Amanatides–Woo traversal), compiled with numba.

ROS-free. The grid is a boolean obstacle array with row 0 at the bottom (y = origin y), as
:class:`cnr_maps.mapio.OccupancyMap`. A ray stops at the boundary of the first obstacle cell it
enters; a ray that leaves the map or reaches ``max_range`` returns ``inf``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def cast_rays(obstacle: np.ndarray, resolution: float, origin_x: float, origin_y: float,
              x: float, y: float, angles: np.ndarray, max_range: float, out: np.ndarray) -> None:
    """Distance from (x, y) to the first obstacle cell along each angle, written into ``out`` [m].

    Args:
        obstacle: bool (rows, cols), row 0 at the bottom.
        resolution: cell size [m]; origin_x, origin_y: lower-left corner of cell (0, 0) [m].
        x, y: ray origin [m]; angles: ray directions in the map frame [rad].
        max_range: rays longer than this return inf [m].
        out: float64 array, same length as ``angles``.
    """
    rows, cols = obstacle.shape
    gx = (x - origin_x) / resolution
    gy = (y - origin_y) / resolution
    max_cells = max_range / resolution
    for i in range(angles.shape[0]):
        dx = math.cos(angles[i])
        dy = math.sin(angles[i])
        cx = int(math.floor(gx))
        cy = int(math.floor(gy))
        if cx < 0 or cy < 0 or cx >= cols or cy >= rows:
            out[i] = np.inf
            continue
        if obstacle[cy, cx]:
            out[i] = 0.0
            continue
        step_x = 1 if dx > 0 else -1
        step_y = 1 if dy > 0 else -1
        if dx != 0.0:
            t_max_x = ((cx + (1 if dx > 0 else 0)) - gx) / dx
            t_delta_x = abs(1.0 / dx)
        else:
            t_max_x = np.inf
            t_delta_x = np.inf
        if dy != 0.0:
            t_max_y = ((cy + (1 if dy > 0 else 0)) - gy) / dy
            t_delta_y = abs(1.0 / dy)
        else:
            t_max_y = np.inf
            t_delta_y = np.inf
        hit = np.inf
        while True:
            if t_max_x < t_max_y:
                t = t_max_x
                t_max_x += t_delta_x
                cx += step_x
            else:
                t = t_max_y
                t_max_y += t_delta_y
                cy += step_y
            if t > max_cells:
                break
            if cx < 0 or cy < 0 or cx >= cols or cy >= rows:
                break
            if obstacle[cy, cx]:
                hit = t * resolution
                break
        out[i] = hit


def circle_hits(x: float, y: float, angles: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Distance along each ray to the nearest of several circles (analytic, vectorised) [m].

    Args:
        x, y: ray origin [m]; angles: (n,) ray directions [rad].
        centres: (k, 2) circle centres [m]; radii: (k,) radii [m].

    Returns:
        (n,) distances, inf where no circle is hit in front of the origin.
    """
    if len(centres) == 0:
        return np.full(angles.shape, np.inf)
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)            # (n, 2)
    rel = np.asarray(centres, dtype=float) - np.array([x, y])         # (k, 2)
    b = d @ rel.T                                                     # (n, k) projection of centre on ray
    c = np.sum(rel * rel, axis=1) - np.asarray(radii, dtype=float) ** 2   # (k,)
    disc = b * b - c
    with np.errstate(invalid='ignore'):
        root = np.sqrt(disc)
    t = np.where(c[None, :] < 0, 0.0, b - root)                       # inside a circle: 0
    t = np.where((disc >= 0) & (b + root > 0) & (t >= 0), t, np.inf)
    return t.min(axis=1)
