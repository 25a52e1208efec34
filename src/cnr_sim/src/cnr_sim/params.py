"""The simulator node's parameters, read in one place (ROS-free: built from a cnr_params Section)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Dict, List

from cnr_params import Section, load_yaml

from cnr_sim.core.battery import BatteryConfig
from cnr_sim.core.depth_camera import DepthCameraConfig
from cnr_maps.pose import Pose2D
from cnr_sim.core.kinematics import BaseLimits
from cnr_sim.core.laser import LaserConfig
from cnr_sim.core.obstacles import MovingObstacle, obstacles_from_config
from cnr_sim.core.plugins import check_spec
from cnr_sim.core.world import WorldConfig


#: the files simulator.launch loads into the simulator's private namespace, in that order
CONFIG_FILES = ('simulator.yaml', 'robot.yaml', 'laser.yaml', 'depth_camera.yaml', 'battery.yaml')


@dataclass
class SimulatorParams:
    map_file: str
    real_time_factor: float
    clock_frequency: float          # Hz of /clock (0: every step)
    initial_pose: Pose2D
    limits: BaseLimits
    world: WorldConfig
    laser: LaserConfig
    laser_frame: str
    laser_offset_z: float
    depth: DepthCameraConfig
    depth_enabled: bool
    depth_frame: str
    battery: BatteryConfig
    battery_rate: float
    battery_interface: str
    battery_cpu_cgroup: str
    battery_cpu_usage: str          # plugin reading the cgroup's CPU seconds (cnr_sim.core.plugins)
    battery_measure_period: float
    battery_enabled: bool
    obstacles: List[MovingObstacle]
    map_frame: str
    odom_frame: str
    footprint_frame: str
    base_frame: str
    base_height: float
    publish_map_to_odom: bool
    seed: int
    command_fence: str              # plugin fencing the velocity commands ('' none; cnr_sim.core.plugins)


def config_section(config_dir: str, **values: Any) -> Section:
    """The simulator's private namespace as simulator.launch fills it from ``config_dir`` (plus ``values``).

    For tools and tests that build the simulator's parts without a launch file.
    """
    data: Dict[str, Any] = {}
    for name in CONFIG_FILES:
        data.update(load_yaml(os.path.join(config_dir, name)))
    data.update(values)
    return Section(data, config_dir)


def read_limits(p: Section) -> BaseLimits:
    """``~base``: the base's limits."""
    base = p.section('base')
    return BaseLimits(
        max_linear=base.number('max_linear', positive=True),
        max_angular=math.radians(base.number('max_angular_deg', positive=True)),
        max_linear_accel=base.number('max_linear_accel', positive=True),
        max_angular_accel=base.number('max_angular_accel', positive=True),
        wheel_separation=base.number('wheel_separation', positive=True),
        watchdog_timeout=base.number('watchdog_timeout', positive=True))


def read_world(p: Section) -> WorldConfig:
    """``~step``, ``~base/radius``, ``~odom/noise_*``."""
    odom = p.section('odom')
    return WorldConfig(radius=p.section('base').number('radius', positive=True),
                       step=p.number('step', positive=True, maximum=0.2),
                       odom_noise_linear=odom.number('noise_linear', nonnegative=True),
                       odom_noise_angular=odom.number('noise_angular', nonnegative=True))


def read_laser(p: Section) -> LaserConfig:
    """``~laser``: the fake laser."""
    ls = p.section('laser')
    offset = ls.vector('offset', 3)
    laser = LaserConfig(beams=ls.integer('beams', minimum=1),
                        fov=math.radians(ls.number('fov_deg', positive=True, maximum=360.0)),
                        min_range=ls.number('min_range', nonnegative=True),
                        max_range=ls.number('max_range', positive=True),
                        rate=ls.number('rate', positive=True),
                        noise_stddev=ls.number('noise_stddev', nonnegative=True),
                        offset_x=offset[0], offset_y=offset[1])
    if laser.min_range >= laser.max_range:
        raise ls.error('min_range', f'must be below max_range ({laser.max_range})')
    return laser


def read_depth_camera(p: Section) -> DepthCameraConfig:
    """``~depth_camera``: the Kinect's depth cloud (its position is the laser's: ``~laser/offset``)."""
    dc = p.section('depth_camera')
    depth = DepthCameraConfig(width=dc.integer('width', minimum=1), height=dc.integer('height', minimum=1),
                              fov_h=math.radians(dc.number('fov_h_deg', positive=True, maximum=170.0)),
                              fov_v=math.radians(dc.number('fov_v_deg', positive=True, maximum=170.0)),
                              min_range=dc.number('min_range', nonnegative=True),
                              max_range=dc.number('max_range', positive=True),
                              rate=dc.number('rate', positive=True),
                              mount_height=p.section('laser').vector('offset', 3)[2])
    if depth.min_range >= depth.max_range:
        raise dc.error('min_range', f'must be below max_range ({depth.max_range})')
    return depth


def read_plugin(p: Section, key: str, optional: bool = False) -> str:
    """A plugin name (``package.module:name``; '' if ``optional``), checked for its form only: it is loaded when
    the node starts (:func:`cnr_sim.core.plugins.load`)."""
    spec = p.string(key)
    problem = check_spec(spec) if spec or not optional else ''
    if problem:
        raise p.error(key, problem)
    return spec


def read_params(p: Section) -> SimulatorParams:
    """Build :class:`SimulatorParams` from the node's private namespace (errors name the field)."""
    base, odom, ls, bat = p.section('base'), p.section('odom'), p.section('laser'), p.section('battery')
    dc = p.section('depth_camera')
    depth_frame = dc.string('frame_id')
    if depth_frame == ls.string('frame_id'):
        raise dc.error('frame_id', f"must differ from laser.frame_id ('{depth_frame}'): it is the optical frame, "
                                   'a child of the laser frame')
    return SimulatorParams(
        map_file=p.string('map_file'),
        real_time_factor=p.number('real_time_factor', nonnegative=True),
        clock_frequency=p.number('clock_frequency', nonnegative=True),
        initial_pose=Pose2D(*p.vector('initial_pose', 3)), limits=read_limits(p), world=read_world(p),
        laser=read_laser(p), laser_frame=ls.string('frame_id'), laser_offset_z=ls.vector('offset', 3)[2],
        depth=read_depth_camera(p), depth_enabled=dc.boolean('enabled'), depth_frame=depth_frame,
        battery=BatteryConfig.from_section(bat),
        battery_rate=bat.number('publish_rate', positive=True),
        battery_interface=bat.string('interface'),
        battery_cpu_cgroup=bat.string('cpu_cgroup'),
        battery_cpu_usage=read_plugin(bat, 'cpu_usage'),
        battery_measure_period=bat.number('measure_period', positive=True),
        battery_enabled=bat.boolean('measure_work'),
        obstacles=obstacles_from_config(p) if p.boolean('enable_obstacles') else [],
        map_frame=p.string('map_frame'), odom_frame=odom.string('frame_id'),
        footprint_frame=odom.string('child_frame_id'),
        base_frame=p.string('base_frame'),
        base_height=base.number('height'),
        publish_map_to_odom=p.boolean('publish_map_to_odom'),
        seed=p.integer('seed'),
        command_fence=read_plugin(p, 'command_fence', optional=True))
