"""The simulated world: one Kobuki robot with a fake Kinect laser in a map with moving obstacles.

ROS-free; :mod:`cnr_sim.node` wraps it. ``step()`` advances sim time by a fixed dt: velocity limits
and watchdog, exact unicycle integration, collision stall against the map's clearance field and the
moving obstacles, odometry (with optional noise), battery.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np

from cnr_sim.core.battery import BatteryModel
from cnr_sim.core.collision import ClearanceField, obstacle_mask
from cnr_sim.core.depth_camera import DepthCamera, DepthCameraConfig
from cnr_maps.pose import Pose2D
from cnr_sim.core.kinematics import BaseLimits, DiffDrive, integrate
from cnr_sim.core.laser import FakeLaser, LaserConfig
from cnr_maps.mapio import OccupancyMap
from cnr_sim.core.obstacles import MovingObstacle, positions


@dataclass
class CollisionEvent:
    """The robot hit something and stalled."""

    time: float
    pose: Pose2D
    speed: float
    obstacle: str


@dataclass
class WorldConfig:
    """Physical parameters of the robot in the world.

    Attributes:
        radius: robot footprint radius [m].
        step: integration step [s].
        odom_noise_linear: odometry noise: relative stddev of the measured linear speed (0.02 = 2 %).
        odom_noise_angular: relative stddev of the measured yaw rate.
    (The TurtleBot 2 values are in config/robot.yaml.)
    """

    radius: float
    step: float
    odom_noise_linear: float
    odom_noise_angular: float


class World:
    """One robot in a map.

    Args:
        grid: the static map.
        limits: base limits; laser: laser parameters; battery: battery model (or None).
        config: world parameters; obstacles: moving obstacles; start: initial pose.
        rng: random generator (noise).
        depth: depth camera parameters (None: no depth camera); it is the Kinect the laser comes from,
            so it sits at the laser's position.
    """

    def __init__(self, grid: OccupancyMap, limits: BaseLimits, laser: LaserConfig, config: WorldConfig,
                 start: Pose2D, obstacles: Optional[List[MovingObstacle]] = None,
                 battery: Optional[BatteryModel] = None, rng: Optional[np.random.Generator] = None,
                 depth: Optional[DepthCameraConfig] = None) -> None:
        self.grid = grid
        self.config = config
        self.rng = rng or np.random.default_rng()
        mask = obstacle_mask(grid)
        self.clearance = ClearanceField(grid, mask)
        self.laser = FakeLaser(laser, mask, grid.resolution, grid.origin, self.rng)
        self.depth = DepthCamera(depth, mask, grid.resolution, grid.origin) if depth is not None else None
        self.base = DiffDrive(limits)
        self.obstacles = list(obstacles or [])
        self.battery = battery
        self.start = start
        self.time = 0.0
        self.pose = Pose2D(start.x, start.y, start.yaw)
        self.odom = Pose2D()
        self.in_contact = False
        self.collisions: List[CollisionEvent] = []
        self.distance = 0.0
        self.steps = 0
        self._scan_period = 1.0 / laser.rate
        self._next_scan = 0.0
        self._depth_period = 1.0 / depth.rate if depth is not None else math.inf
        self._next_depth = 0.0
        problem = self.pose_problem(start)
        if problem:
            raise ValueError(f'start pose ({start.x}, {start.y}): {problem}')

    # -- queries -------------------------------------------------------------------------------
    def pose_problem(self, pose: Pose2D) -> str:
        """Why a pose is not a valid robot pose ('' if it is)."""
        if not all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw)):
            return 'not finite'
        if not self.grid.contains(pose.x, pose.y):
            return 'outside the map'
        if self.clearance.collides(pose.x, pose.y, self.config.radius):
            return 'in collision with the map'
        return ''

    def map_to_odom(self) -> Pose2D:
        """Transform map -> odom so that map -> base_footprint is the ground truth (perfect localization)."""
        return self.pose.compose(self.odom.inverse())

    def obstacle_positions(self):
        return positions(self.obstacles, self.time)

    def scan_due(self) -> bool:
        return self.time + 1e-9 >= self._next_scan

    def scan(self) -> np.ndarray:
        """Laser ranges at the current pose (also schedules the next scan)."""
        self._next_scan = self.time + self._scan_period
        centres, radii = self.obstacle_positions()
        return self.laser.scan(self.pose.x, self.pose.y, self.pose.yaw, centres, radii)

    def depth_due(self) -> bool:
        return self.depth is not None and self.time + 1e-9 >= self._next_depth

    def depth_frame(self) -> np.ndarray:
        """Depth camera cloud at the current pose (also schedules the next frame).

        Frames follow a fixed schedule (``k / rate``), so the mean rate is ``rate`` even when the period
        is not a multiple of the step; each frame is taken at the first step at or after its time.
        """
        self._next_depth += self._depth_period
        if self._next_depth <= self.time:                 # fell behind (first frame): restart the schedule
            self._next_depth = self.time + self._depth_period
        centres, radii = self.obstacle_positions()
        sx, sy, syaw = self.laser.sensor_pose(self.pose.x, self.pose.y, self.pose.yaw)
        return self.depth.frame(sx, sy, syaw, centres, radii)

    # -- commands ------------------------------------------------------------------------------
    def command(self, v: float, w: float) -> None:
        """Velocity command at the current sim time (ValueError when not finite)."""
        self.base.command(v, w, self.time)

    def teleport(self, pose: Pose2D, reset_odometry: bool = False) -> str:
        """Move the robot; returns '' or the reason for refusing."""
        problem = self.pose_problem(pose)
        if problem:
            return problem
        delta = self.pose.inverse().compose(pose)
        self.pose = Pose2D(pose.x, pose.y, pose.yaw)
        self.odom = Pose2D() if reset_odometry else self.odom.compose(delta)
        self.base.stop()
        self.in_contact = False
        return ''

    def reset(self) -> None:
        """Back to the start pose with odometry zeroed (stage_ros reset_positions)."""
        self.teleport(self.start, reset_odometry=True)

    # -- simulation ----------------------------------------------------------------------------
    def _hits_obstacle(self, pose: Pose2D) -> str:
        if self.clearance.collides(pose.x, pose.y, self.config.radius):
            return 'map'
        for ob in self.obstacles:
            ox, oy = ob.position(self.time)
            if math.hypot(pose.x - ox, pose.y - oy) < self.config.radius + ob.radius:
                return ob.name
        return ''

    def step(self) -> Optional[CollisionEvent]:
        """Advance by one step; returns a collision event when the robot newly hits something."""
        dt = self.config.step
        v0, w0 = self.base.v, self.base.w
        v, w = self.base.update(self.time, dt)
        self.time += dt
        self.steps += 1
        event = None
        if v != 0.0 or w != 0.0:
            nxt = integrate(self.pose, v, w, dt)
            hit = self._hits_obstacle(nxt)
            # moving away from a contact is allowed (the new pose has more clearance)
            if hit and (not self.in_contact or self.clearance.clearance(nxt.x, nxt.y) <=
                        self.clearance.clearance(self.pose.x, self.pose.y)):
                if not self.in_contact:
                    event = CollisionEvent(self.time, Pose2D(self.pose.x, self.pose.y, self.pose.yaw), v, hit)
                    self.collisions.append(event)
                self.in_contact = True
                self.base.v = self.base.w = 0.0
                v = w = 0.0
            else:
                self.in_contact = bool(hit)
                self.distance += abs(v) * dt
                self.pose = nxt
                vo, wo = v, w
                if self.config.odom_noise_linear > 0 or self.config.odom_noise_angular > 0:
                    vo = v * (1.0 + self.rng.normal(0.0, self.config.odom_noise_linear))
                    wo = w * (1.0 + self.rng.normal(0.0, self.config.odom_noise_angular))
                self.odom = integrate(self.odom, vo, wo, dt)
        if self.battery is not None:
            self.battery.step(dt, v, w, (v - v0) / dt, (w - w0) / dt)
        return event
