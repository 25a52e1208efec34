"""The simulator node's parameters, read in one place (ROS-free: built from a cnr_params Section)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Tuple

from cnr_params import Section

from cnr_sim.core.battery import BatteryConfig
from cnr_maps.pose import Pose2D
from cnr_sim.core.kinematics import BaseLimits
from cnr_sim.core.laser import LaserConfig
from cnr_sim.core.obstacles import MovingObstacle, obstacles_from_config
from cnr_sim.core.world import WorldConfig


@dataclass
class SimulatorParams:
    map_file: str
    real_time_factor: float
    initial_pose: Pose2D
    limits: BaseLimits
    world: WorldConfig
    laser: LaserConfig
    laser_frame: str
    laser_offset_z: float
    battery: BatteryConfig
    battery_rate: float
    battery_interface: str
    battery_measure_period: float
    battery_enabled: bool
    obstacles: List[MovingObstacle]
    map_frame: str = 'map'
    odom_frame: str = 'odom'
    footprint_frame: str = 'base_footprint'
    base_frame: str = 'base_link'
    base_height: float = 0.0102
    publish_map_to_odom: bool = True
    seed: int = 0
    frames: Tuple[str, ...] = field(default_factory=tuple)


def read_params(p: Section) -> SimulatorParams:
    """Build :class:`SimulatorParams` from the node's private namespace (errors name the field)."""
    base = p.section('base', {})
    limits = BaseLimits(
        max_linear=base.number('max_linear', 0.70, positive=True),
        max_angular=math.radians(base.number('max_angular_deg', 180.0, positive=True)),
        max_linear_accel=base.number('max_linear_accel', 1.0, positive=True),
        max_angular_accel=base.number('max_angular_accel', 2.0, positive=True),
        wheel_separation=base.number('wheel_separation', 0.230, positive=True),
        watchdog_timeout=base.number('watchdog_timeout', 0.6, positive=True))
    odom = p.section('odom', {})
    world = WorldConfig(radius=base.number('radius', 0.178, positive=True),
                        step=p.number('step', 0.02, positive=True, maximum=0.2),
                        odom_noise_linear=odom.number('noise_linear', 0.0, nonnegative=True),
                        odom_noise_angular=odom.number('noise_angular', 0.0, nonnegative=True))
    ls = p.section('laser', {})
    offset = ls.vector('offset', 3, [-0.087, 0.0125, 0.287])
    beams = ls.integer('beams', 640, minimum=1)
    laser = LaserConfig(beams=beams, fov=math.radians(ls.number('fov_deg', 58.0, positive=True, maximum=360.0)),
                        min_range=ls.number('min_range', 0.45, nonnegative=True),
                        max_range=ls.number('max_range', 5.0, positive=True),
                        rate=ls.number('rate', 10.0, positive=True),
                        noise_stddev=ls.number('noise_stddev', 0.0, nonnegative=True),
                        offset_x=offset[0], offset_y=offset[1])
    if laser.min_range >= laser.max_range:
        raise ls.error('min_range', f'must be below max_range ({laser.max_range})')
    bat = p.section('battery', {})
    pose = p.vector('initial_pose', 3, [0.5, 0.0, 0.0])
    return SimulatorParams(
        map_file=p.string('map_file'),
        real_time_factor=p.number('real_time_factor', 1.0, nonnegative=True),
        initial_pose=Pose2D(*pose), limits=limits, world=world, laser=laser,
        laser_frame=ls.string('frame_id', 'camera_depth_frame'), laser_offset_z=offset[2],
        battery=BatteryConfig.from_section(bat),
        battery_rate=bat.number('publish_rate', 1.0, positive=True),
        battery_interface=bat.string('interface', ''),
        battery_measure_period=bat.number('measure_period', 1.0, positive=True),
        battery_enabled=bat.boolean('measure_work', True),
        obstacles=obstacles_from_config(p) if p.boolean('enable_obstacles', False) else [],
        map_frame=p.string('map_frame', 'map'), odom_frame=odom.string('frame_id', 'odom'),
        footprint_frame=odom.string('child_frame_id', 'base_footprint'),
        base_frame=p.string('base_frame', 'base_link'),
        base_height=base.number('height', 0.0102),
        publish_map_to_odom=p.boolean('publish_map_to_odom', True),
        seed=p.integer('seed', 0))
