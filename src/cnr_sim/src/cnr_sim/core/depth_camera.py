"""Kinect-like depth camera: an organised point cloud ray-cast on the occupancy grid.

ROS-free. The world is 2-D, so the camera is a pinhole camera looking horizontally whose pixel columns
each share one azimuth: one ray per column is cast on the grid (and the moving discs) with
:func:`cnr_sim.core.raycast.cast_rays`, and every pixel of the column sees the same wall, at a height
given by its row. Conventions (documented in the package README):

* walls and moving obstacles are vertical columns taller than anything the camera sees within
  ``max_range``; the floor is the plane z = 0 of base_footprint, so pixels looking down see the floor
  where it is nearer than the wall (floor points have z = 0; a navigation source filters them by height);
* depth is the distance along the optical axis, as a Kinect reports it; pixels whose depth is outside
  ``[min_range, max_range]`` (too close, or nothing within range) are NaN, as openni's organised clouds;
* the cloud is organised (``height`` x ``width``, ``is_dense`` false) in the optical frame (x right,
  y down, z forward, REP 103), float32 x, y, z: ``12 * width * height`` bytes of data per frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cnr_sim.core.raycast import cast_rays, circle_hits

#: bytes per point: x, y, z as float32
POINT_STEP = 12


@dataclass
class DepthCameraConfig:
    """Parameters of the depth camera (the TurtleBot 2 Kinect values are in config/depth_camera.yaml).

    Attributes:
        width / height: image size [pixels].
        fov_h / fov_v: horizontal / vertical field of view [rad] (pinhole: edge to edge of the image).
        min_range / max_range: usable depth interval [m].
        rate: frame rate [Hz].
        mount_height: height of the optical centre above the floor [m].
    """

    width: int
    height: int
    fov_h: float
    fov_v: float
    min_range: float
    max_range: float
    rate: float
    mount_height: float
    column_slope: np.ndarray = field(init=False, repr=False)
    row_slope: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        # pixel centres of a pinhole camera: tan of the angle left of (up from) the optical axis
        fx = 0.5 * self.width / math.tan(0.5 * self.fov_h)
        fy = 0.5 * self.height / math.tan(0.5 * self.fov_v)
        self.column_slope = (0.5 * self.width - (np.arange(self.width) + 0.5)) / fx
        self.row_slope = (0.5 * self.height - (np.arange(self.height) + 0.5)) / fy

    @property
    def frame_bytes(self) -> int:
        """Size of one frame's point data [bytes]."""
        return POINT_STEP * self.width * self.height


class DepthCamera:
    """Produces organised point clouds for a sensor pose.

    Args:
        config: the camera's parameters.
        obstacle: bool grid (row 0 at the bottom) of the static map's obstacles.
        resolution, origin: the map's geometry ([m], (x, y) [m]).
    """

    def __init__(self, config: DepthCameraConfig, obstacle: np.ndarray, resolution: float, origin) -> None:
        self.config = config
        self.obstacle = np.ascontiguousarray(obstacle, dtype=np.bool_)
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        c = config
        self._azimuth = np.arctan(c.column_slope)
        self._stretch = np.sqrt(1.0 + c.column_slope ** 2)        # horizontal distance per metre of depth
        self._cast_range = c.max_range * float(self._stretch.max())
        with np.errstate(divide='ignore'):
            floor = np.where(c.row_slope < 0, c.mount_height / -c.row_slope, np.inf)
        self._floor_depth = floor[:, None].astype(np.float32)       # (height, 1) depth at which a row meets the floor
        # (height, width, 3) point per metre of depth, optical frame: right, down, forward
        self._rays = np.empty((c.height, c.width, 3), dtype=np.float32)
        self._rays[..., 0] = -c.column_slope[None, :]
        self._rays[..., 1] = -c.row_slope[:, None]
        self._rays[..., 2] = 1.0
        self._buf = np.empty(c.width)

    def frame(self, x: float, y: float, yaw: float, circles: Optional[np.ndarray] = None,
              radii: Optional[np.ndarray] = None) -> np.ndarray:
        """One frame for the sensor at (x, y) with heading ``yaw`` (map frame) and optional moving discs.

        Returns:
            float32 (height, width, 3): x, y, z in the optical frame [m], NaN where there is no valid depth.
        """
        c = self.config
        angles = yaw + self._azimuth
        cast_rays(self.obstacle, self.resolution, self.origin[0], self.origin[1], x, y, angles,
                  self._cast_range, self._buf)
        horizontal = self._buf
        if circles is not None and len(circles):
            horizontal = np.minimum(horizontal, circle_hits(x, y, angles, circles, radii))
        wall = (horizontal / self._stretch).astype(np.float32)                 # (width,) depth of the column's wall
        depth = np.minimum(wall[None, :], self._floor_depth)                   # (height, width)
        depth[(depth < c.min_range) | (depth > c.max_range)] = np.nan
        return self._rays * depth[..., None]
