"""Planar poses, rigid transforms and goal validation (ROS-free).

Angles are in radians, lengths in metres. Quaternions are (x, y, z, w) tuples as in
geometry_msgs/Quaternion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

Quaternion = Tuple[float, float, float, float]


def normalize_angle(angle):
    """Wrap angles (scalar or array) to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi if isinstance(angle, np.ndarray) \
        else (angle + math.pi) % (2.0 * math.pi) - math.pi


def yaw_to_quaternion(yaw: float) -> Quaternion:
    """Quaternion (x, y, z, w) of a rotation by ``yaw`` [rad] about z."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def quaternion_to_yaw(q: Quaternion) -> float:
    """Yaw [rad] of a quaternion (x, y, z, w) (roll and pitch ignored)."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_problem(q: Quaternion) -> Optional[str]:
    """Why a goal orientation is unusable for planar navigation, or None if it is fine.

    Same checks, in the same order, as ``MoveBase::isQuaternionValid`` (move_base.cpp): NaN or
    infinite components, a length close to zero, and a z-axis that is not close to vertical
    after normalisation.
    """
    if not all(math.isfinite(v) for v in q):
        return 'Quaternion has nans or infs... discarding as a navigation goal'
    norm = math.sqrt(sum(v * v for v in q))
    if norm < 1e-6:
        return 'Quaternion has length close to zero... discarding as navigation goal'
    x, y, z, w = (v / norm for v in q)
    # z-axis of the rotated frame: third column of the rotation matrix, dotted with (0, 0, 1)
    dot = 1.0 - 2.0 * (x * x + y * y)
    if abs(dot - 1.0) > 1e-3:
        return 'Quaternion is invalid... for navigation the z-axis of the quaternion must be close to vertical.'
    return None


@dataclass(frozen=True)
class Pose2D:
    """A planar pose: position ``x``, ``y`` [m] and heading ``yaw`` [rad]."""

    x: float
    y: float
    yaw: float = 0.0

    def distance(self, other: 'Pose2D') -> float:
        """Euclidean distance [m] between the positions."""
        return math.hypot(self.x - other.x, self.y - other.y)

    def is_finite(self) -> bool:
        return math.isfinite(self.x) and math.isfinite(self.y) and math.isfinite(self.yaw)

    def compose(self, other: 'Pose2D') -> 'Pose2D':
        """``self * other``: ``other`` expressed in the frame ``self`` is given in."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(self.x + c * other.x - s * other.y, self.y + s * other.x + c * other.y,
                      float(normalize_angle(self.yaw + other.yaw)))

    def inverse(self) -> 'Pose2D':
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, -self.yaw)

    def apply(self, xs: np.ndarray, ys: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Transform point arrays given in the child frame into this pose's parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.x + c * xs - s * ys, self.y + s * xs + c * ys


IDENTITY = Pose2D(0.0, 0.0, 0.0)


def transform_path(path: np.ndarray, transform: Pose2D) -> np.ndarray:
    """Apply ``transform`` to an (N, 3) array of (x, y, yaw) poses."""
    if path.size == 0:
        return path.reshape(0, 3)
    xs, ys = transform.apply(path[:, 0], path[:, 1])
    return np.column_stack((xs, ys, normalize_angle(path[:, 2] + transform.yaw)))
