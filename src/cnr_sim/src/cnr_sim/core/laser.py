"""Fake Kinect laser (depthimage_to_laserscan on a TurtleBot 2), ray-cast against the occupancy grid.

ROS-free. Conventions (documented in the package README):
* ``angle_increment = fov / (beams - 1)``, centred on the sensor's x axis (Stage's convention);
* a beam that hits nothing within ``max_range`` returns ``max_range`` (Stage's convention, so that
  costmaps clear along it); a hit closer than ``min_range`` returns NaN, as depthimage_to_laserscan
  reports depth pixels it cannot use.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cnr_sim.core.raycast import cast_rays, circle_hits


@dataclass
class LaserConfig:
    """Parameters of the fake laser (the TurtleBot 2 Kinect values are in config/laser.yaml).

    Attributes:
        beams: number of beams.
        fov: field of view [rad].
        min_range / max_range: [m].
        rate: publication rate [Hz].
        noise_stddev: Gaussian range noise [m] (0 = none).
        offset_x, offset_y: sensor position in base_footprint [m].
    """

    beams: int
    fov: float
    min_range: float
    max_range: float
    rate: float
    noise_stddev: float
    offset_x: float
    offset_y: float
    relative_angles: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.relative_angles = -0.5 * self.fov + np.arange(self.beams) * self.angle_increment

    @property
    def angle_min(self) -> float:
        return -0.5 * self.fov

    @property
    def angle_increment(self) -> float:
        return self.fov / (self.beams - 1) if self.beams > 1 else 0.0


class FakeLaser:
    """Produces range arrays for a robot pose.

    Args:
        config: the laser's parameters.
        obstacle: bool grid (row 0 at the bottom) of the static map's obstacles.
        resolution, origin: the map's geometry ([m], (x, y) [m]).
        rng: random generator for the noise.
    """

    def __init__(self, config: LaserConfig, obstacle: np.ndarray, resolution: float, origin,
                 rng: Optional[np.random.Generator] = None) -> None:
        self.config = config
        self.obstacle = np.ascontiguousarray(obstacle, dtype=np.bool_)
        self.resolution = float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        self.rng = rng or np.random.default_rng()
        self._buf = np.empty(config.beams)

    def sensor_pose(self, x: float, y: float, yaw: float):
        c = self.config
        cs, sn = math.cos(yaw), math.sin(yaw)
        return x + cs * c.offset_x - sn * c.offset_y, y + sn * c.offset_x + cs * c.offset_y, yaw

    def scan(self, x: float, y: float, yaw: float, circles: Optional[np.ndarray] = None,
             radii: Optional[np.ndarray] = None) -> np.ndarray:
        """Ranges [m] for the robot (base_footprint) at (x, y, yaw) with optional moving discs."""
        c = self.config
        sx, sy, syaw = self.sensor_pose(x, y, yaw)
        angles = syaw + c.relative_angles
        cast_rays(self.obstacle, self.resolution, self.origin[0], self.origin[1], sx, sy, angles,
                  c.max_range, self._buf)
        ranges = self._buf.copy()
        if circles is not None and len(circles):
            np.minimum(ranges, circle_hits(sx, sy, angles, circles, radii), out=ranges)
        if c.noise_stddev > 0:
            ranges += self.rng.normal(0.0, c.noise_stddev, ranges.shape)
        ranges[~(ranges <= c.max_range)] = c.max_range
        ranges[ranges < c.min_range] = np.nan
        return ranges
