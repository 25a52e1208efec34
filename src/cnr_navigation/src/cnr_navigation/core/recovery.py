"""move_base's recovery behaviours as non-blocking steppers (ROS-free).

move_base runs a recovery's ``runBehavior()`` to completion inside its control loop; here each
behaviour is stepped once per control cycle so the state machine stays testable with a fake
clock. Defaults follow ``clear_costmap_recovery`` and ``rotate_recovery`` (noetic).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Protocol, Tuple

from cnr_navigation.core.geometry import Pose2D, normalize_angle

Velocity = Tuple[float, float]


class RecoveryBackend(Protocol):
    """What recoveries need from the navigation node."""

    def robot_pose(self) -> Optional[Pose2D]:
        """Robot pose in the local costmap frame (None if unknown)."""

    def clear_costmaps(self, affected_maps: str, reset_distance: float, layer_names: List[str],
                       invert_area_to_clear: bool) -> None:
        """Reset the named layers of the 'global', 'local' or 'both' costmaps outside (inside)
        a square of side ``reset_distance`` [m] around the robot."""

    def in_collision(self, pose: Pose2D) -> bool:
        """True if the footprint at ``pose`` touches an inscribed/lethal/unknown cell of the local costmap."""


@dataclass
class StepResult:
    """One recovery step: ``cmd`` to publish (None for nothing) and whether the behaviour ended."""

    cmd: Optional[Velocity]
    done: bool
    message: str = ''


class Recovery:
    """Base class: ``start`` then ``step`` once per control cycle until ``done``."""

    name: str = ''
    type: str = ''

    def start(self, now: float) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def step(self, now: float) -> StepResult:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass
class ClearCostmapConfig:
    """``~<name>/*`` of a ClearCostmapRecovery (reset_distance [m])."""

    reset_distance: float
    affected_maps: str
    layer_names: List[str]
    invert_area_to_clear: bool
    force_updating: bool


class ClearCostmapRecovery(Recovery):
    """Resets obstacle layers outside a window around the robot; finishes in one step."""

    type = 'clear_costmap_recovery/ClearCostmapRecovery'

    def __init__(self, name: str, cfg: ClearCostmapConfig, backend: RecoveryBackend) -> None:
        self.name = name
        self.cfg = cfg
        self.backend = backend

    def start(self, now: float) -> None:
        pass

    def step(self, now: float) -> StepResult:
        c = self.cfg
        self.backend.clear_costmaps(c.affected_maps, c.reset_distance, list(c.layer_names), c.invert_area_to_clear)
        return StepResult(None, True, f'Clearing {c.affected_maps} costmap{"s" if c.affected_maps == "both" else ""} '
                                      f'outside a square ({c.reset_distance:.2f}m) large centered on the robot.')


@dataclass
class RotateConfig:
    """RotateRecovery parameters (``~<name>/*`` and the ``~TrajectoryPlannerROS/*`` it borrows).

    Attributes:
        sim_granularity: angular step for the collision check [rad].
        frequency: rate move_base's RotateRecovery publishes at [Hz] (here: the control rate).
        acc_lim_th: angular acceleration limit [rad/s^2].
        max_rotational_vel / min_in_place_rotational_vel: speed limits [rad/s].
        yaw_goal_tolerance: how close to a full turn counts as done [rad].
    """

    sim_granularity: float
    frequency: float
    acc_lim_th: float
    max_rotational_vel: float
    min_in_place_rotational_vel: float
    yaw_goal_tolerance: float


class RotateRecovery(Recovery):
    """Turns the robot 360 degrees in place (``rotate_recovery.cpp``): first past 180 degrees, then
    back to the start heading, at sqrt(2 acc dist_left) clipped to the limits; stops if the
    footprint would collide."""

    type = 'rotate_recovery/RotateRecovery'

    def __init__(self, name: str, cfg: RotateConfig, backend: RecoveryBackend) -> None:
        self.name = name
        self.cfg = cfg
        self.backend = backend
        self._start_angle: Optional[float] = None
        self._got_180 = False

    def start(self, now: float) -> None:
        pose = self.backend.robot_pose()
        self._start_angle = pose.yaw if pose is not None else None
        self._got_180 = False

    def step(self, now: float) -> StepResult:
        c = self.cfg
        pose = self.backend.robot_pose()
        if pose is None or self._start_angle is None:
            return StepResult((0.0, 0.0), True, 'Rotate recovery: no robot pose, giving up.')
        current = pose.yaw
        start = self._start_angle
        if not self._got_180:
            distance_to_180 = abs(float(normalize_angle(start + math.pi - current)))
            dist_left = math.pi + distance_to_180
            if distance_to_180 < c.yaw_goal_tolerance:
                self._got_180 = True
        else:
            dist_left = abs(float(normalize_angle(start - current)))
            if dist_left <= c.yaw_goal_tolerance:
                return StepResult((0.0, 0.0), True, 'Rotate recovery finished.')
        if self.backend.in_collision(pose):
            return StepResult((0.0, 0.0), True,
                              "Rotate recovery can't rotate in place because there is a potential collision.")
        vel = math.sqrt(2.0 * c.acc_lim_th * dist_left)
        vel = min(max(vel, c.min_in_place_rotational_vel), c.max_rotational_vel)
        return StepResult((0.0, vel), False)
