"""Kobuki differential-drive kinematics with velocity/acceleration limits and a command watchdog.

ROS-free. Units: metres, seconds, radians. The base integrates the unicycle model exactly over a
fixed step (arc of constant curvature), as the Kobuki firmware's odometry does per 20 ms packet.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from cnr_maps.pose import Pose2D, wrap_angle  # noqa: F401 (Pose2D: the type integrate() works on)


@dataclass
class BaseLimits:
    """Limits of the base (the Kobuki / TurtleBot values are in config/robot.yaml ``base``).

    Attributes:
        max_linear: maximum |v| [m/s].
        max_angular: maximum |w| [rad/s].
        max_linear_accel: maximum |dv/dt| [m/s^2].
        max_angular_accel: maximum |dw/dt| [rad/s^2].
        wheel_separation: distance between the wheels [m].
        watchdog_timeout: the base stops when no command arrived for this long [s].
    """

    max_linear: float
    max_angular: float
    max_linear_accel: float
    max_angular_accel: float
    wheel_separation: float
    watchdog_timeout: float


def integrate(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """Exact unicycle integration of a constant (v, w) over dt."""
    if abs(w) < 1e-9:
        return Pose2D(pose.x + v * dt * math.cos(pose.yaw), pose.y + v * dt * math.sin(pose.yaw), pose.yaw)
    yaw2 = pose.yaw + w * dt
    r = v / w
    return Pose2D(pose.x + r * (math.sin(yaw2) - math.sin(pose.yaw)),
                  pose.y - r * (math.cos(yaw2) - math.cos(pose.yaw)), wrap_angle(yaw2))


def _approach(current: float, target: float, max_step: float) -> float:
    if target > current + max_step:
        return current + max_step
    if target < current - max_step:
        return current - max_step
    return target


class DiffDrive:
    """Velocity state of the base: commands in, limited (v, w) out.

    Args:
        limits: the base's limits.
    """

    def __init__(self, limits: BaseLimits) -> None:
        self.limits = limits
        self.v = 0.0
        self.w = 0.0
        self.cmd_v = 0.0
        self.cmd_w = 0.0
        self.cmd_time = -math.inf

    @staticmethod
    def valid_command(v: float, w: float) -> bool:
        """A command is usable when both components are finite numbers."""
        return math.isfinite(v) and math.isfinite(w)

    def command(self, v: float, w: float, now: float) -> None:
        """Set the commanded velocity at sim time ``now`` (clamped to the speed limits).

        Raises:
            ValueError: on NaN or infinite components (callers warn and drop the message).
        """
        if not self.valid_command(v, w):
            raise ValueError(f'non-finite velocity command ({v}, {w})')
        lim = self.limits
        self.cmd_v = min(max(v, -lim.max_linear), lim.max_linear)
        self.cmd_w = min(max(w, -lim.max_angular), lim.max_angular)
        self.cmd_time = now

    def watchdog_expired(self, now: float) -> bool:
        return now - self.cmd_time > self.limits.watchdog_timeout

    def stop(self) -> None:
        """Immediate stop (collision stall, teleport, reset)."""
        self.v = self.w = self.cmd_v = self.cmd_w = 0.0

    def update(self, now: float, dt: float) -> tuple:
        """Advance the velocity by one step toward the command; returns (v, w) for the step."""
        lim = self.limits
        tv, tw = (0.0, 0.0) if self.watchdog_expired(now) else (self.cmd_v, self.cmd_w)
        self.v = _approach(self.v, tv, lim.max_linear_accel * dt)
        self.w = _approach(self.w, tw, lim.max_angular_accel * dt)
        return self.v, self.w

    def wheel_speeds(self) -> tuple:
        """(left, right) wheel rim speeds [m/s]."""
        half = 0.5 * self.limits.wheel_separation * self.w
        return self.v - half, self.v + half
