"""Rigid transforms of paths and goal validation (ROS-free).

``Pose2D``, angles and quaternions come from :mod:`cnr_maps.pose` (re-exported here for this package).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from cnr_maps.pose import Pose2D, Quaternion, quaternion_to_yaw, yaw_to_quaternion  # noqa: F401
from cnr_maps.pose import wrap_angle as normalize_angle  # noqa: F401


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


IDENTITY = Pose2D(0.0, 0.0, 0.0)


def transform_path(path: np.ndarray, transform: Pose2D) -> np.ndarray:
    """Apply ``transform`` to an (N, 3) array of (x, y, yaw) poses."""
    if path.size == 0:
        return path.reshape(0, 3)
    xs, ys = transform.apply(path[:, 0], path[:, 1])
    return np.column_stack((xs, ys, normalize_angle(path[:, 2] + transform.yaw)))


def quaternion_to_matrix(q: Quaternion) -> np.ndarray:
    """3 x 3 rotation matrix of a quaternion (x, y, z, w); normalised first."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / math.sqrt(sum(v * v for v in q))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
