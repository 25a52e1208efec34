"""Planar poses and yaw <-> quaternion (ROS-free).

Angles are in radians, lengths in metres. Quaternions are plain ``(x, y, z, w)`` tuples in the order of
geometry_msgs/Quaternion: node modules build the message with ``Quaternion(*yaw_to_quaternion(yaw))``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Tuple, Union

import numpy as np

Quaternion = Tuple[float, float, float, float]
Angle = Union[float, np.ndarray]


def wrap_angle(angle: Angle) -> Angle:
    """Angle (a float or an array of them) wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def yaw_to_quaternion(yaw: float) -> Quaternion:
    """Quaternion (x, y, z, w) of a rotation by ``yaw`` [rad] about z."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def quaternion_to_yaw(q: Quaternion) -> float:
    """Yaw [rad] of a quaternion (x, y, z, w) (roll and pitch ignored)."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@dataclass(frozen=True)
class Pose2D:
    """A planar pose: position ``x``, ``y`` [m] and heading ``yaw`` [rad]."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def distance(self, other: 'Pose2D') -> float:
        """Euclidean distance [m] between the positions."""
        return math.hypot(self.x - other.x, self.y - other.y)

    def is_finite(self) -> bool:
        return math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.yaw)

    def compose(self, other: 'Pose2D') -> 'Pose2D':
        """``self ⊕ other``: ``other`` expressed in the frame ``self`` is given in."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(self.x + c * other.x - s * other.y, self.y + s * other.x + c * other.y,
                      float(wrap_angle(self.yaw + other.yaw)))

    def inverse(self) -> 'Pose2D':
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, float(wrap_angle(-self.yaw)))

    def apply(self, xs: np.ndarray, ys: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Transform point arrays given in the child frame into this pose's parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.x + c * xs - s * ys, self.y + s * xs + c * ys
