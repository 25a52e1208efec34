"""Costmap2DROS look-alike: a :class:`LayeredCostmap` fed by ``map``, laser scans and point clouds, published
as nav_msgs/OccupancyGrid, with dynamic_reconfigure servers for the costmap and each layer."""
from __future__ import annotations

import dataclasses
import threading
import time
from typing import Callable, Dict, List, Optional

import message_filters
import numpy as np
import rospy
from dynamic_reconfigure.server import Server as ReconfigureServer
from geometry_msgs.msg import PolygonStamped
from map_msgs.msg import OccupancyGridUpdate
from nav_msgs.msg import OccupancyGrid
from sensor_msgs.msg import LaserScan, PointCloud2

from cnr_navigation.cfg import Costmap2DConfig, GenericPluginConfig, InflationPluginConfig, ObstaclePluginConfig
from cnr_navigation.core.costmap import (INSCRIBED_INFLATED_OBSTACLE, GridGeometry, LayeredCostmap, Observation,
                                         circle_footprint, occupancy_values, scan_to_observation)
from cnr_navigation.core.geometry import IDENTITY, Pose2D
from cnr_navigation.core.param_reader import CostmapParams, SourceParams, parse_footprint
from cnr_navigation.core.pointcloud import cloud_to_observation, cloud_xyz
from cnr_navigation.core.planner import PlanningGrid
from cnr_navigation.ros_io import TfHelper, footprint_msg


#: message class of each observation source ``data_type`` (param_tables.SOURCE_DATA_TYPES)
MESSAGE_TYPES = {'LaserScan': LaserScan, 'PointCloud2': PointCloud2}


class _Source:
    """One observation source: a message_filters cache of its scans or clouds."""

    def __init__(self, params: SourceParams) -> None:
        self.params = params
        self.subscriber = message_filters.Subscriber(params.topic, MESSAGE_TYPES[params.data_type], queue_size=5)
        self.cache = message_filters.Cache(self.subscriber, cache_size=20)
        self.next_stamp = rospy.Time(0)          # messages at or after this stamp are new
        self.max_obstacle_height = params.layer.max_obstacle_height   # as configured for the source

    def new_scans(self) -> List:
        msgs = list(zip(list(self.cache.cache_msgs), list(self.cache.cache_times)))
        return [m for m, t in msgs if t >= self.next_stamp]

    def last_time(self) -> Optional[rospy.Time]:
        times = list(self.cache.cache_times)
        return times[-1] if times else None


class CostmapROS:
    """A costmap in namespace ``~<name>``: subscriptions, update thread, publishers, reconfigure servers.

    Args:
        params: the costmap's parameters (read by :func:`read_navigation_params`).
        tf: tf helper.
        active: returns False while move_base is idle with ``shutdown_costmaps`` set (updates pause).
        publishing: returns False while the costmap must not be published (a migration standby: it updates
            from the sensors but holds its output back); nothing is published before :meth:`open_publishers`.
    """

    def __init__(self, params: CostmapParams, tf: TfHelper, active: Callable[[], bool] = lambda: True,
                 publishing: Callable[[], bool] = lambda: True) -> None:
        self.params = params
        self.name = params.name
        self.ns = f'~{params.name}'
        self.tf = tf
        self.active = active
        self.publishing = publishing
        self.lock = threading.RLock()
        self.costmap = LayeredCostmap(params.config, params.name)
        self.map_frame = 'map'
        self.unknown_mask: Optional[np.ndarray] = None
        self.has_map = False
        self.robot: Optional[Pose2D] = None
        self._published_geometry: Optional[GridGeometry] = None
        self._published_values: Optional[np.ndarray] = None
        self._next_publish = 0.0
        self.update_time = 0.0                    # wall time of the last update [s] (for the bench/README)
        cfg = params.config
        self.footprint = params.footprint or circle_footprint(cfg.robot_radius)

        self.costmap_pub: Optional[rospy.Publisher] = None       # open_publishers()
        self.updates_pub: Optional[rospy.Publisher] = None
        self.footprint_pub: Optional[rospy.Publisher] = None
        self.map_sub = None
        if cfg.static_layer is not None:
            self.map_sub = rospy.Subscriber(params.map_topic, OccupancyGrid, self._on_map, queue_size=1)
        self.sources = [_Source(s) for s in params.sources]

        # dynamic_reconfigure: one server per layer and one for the costmap, in costmap_2d's namespaces
        self.servers: List[ReconfigureServer] = []
        for pname, kind in params.plugins:
            if kind == 'static':
                self.servers.append(ReconfigureServer(GenericPluginConfig, self._on_static_cfg,
                                                      f'{self.ns}/{pname}'))
            elif kind == 'obstacle':
                self.servers.append(ReconfigureServer(ObstaclePluginConfig, self._on_obstacle_cfg,
                                                      f'{self.ns}/{pname}'))
            else:
                self.servers.append(ReconfigureServer(InflationPluginConfig, self._on_inflation_cfg,
                                                      f'{self.ns}/{pname}'))
        self.servers.append(ReconfigureServer(Costmap2DConfig, self._on_costmap_cfg, self.ns))

        self._thread = threading.Thread(target=self._update_loop, name=f'{self.name}_update', daemon=True)
        self._thread.start()

    def open_publishers(self, publisher: Callable[..., rospy.Publisher] = rospy.Publisher) -> None:
        """Create the output topics with ``publisher`` (rospy.Publisher, or a managed instance's factory that
        marks the connections with the instance)."""
        self.updates_pub = publisher(f'{self.ns}/costmap_updates', OccupancyGridUpdate, queue_size=1)
        self.footprint_pub = publisher(f'{self.ns}/footprint', PolygonStamped, queue_size=1)
        self.costmap_pub = publisher(f'{self.ns}/costmap', OccupancyGrid, queue_size=1, latch=True)

    # -- inputs -----------------------------------------------------------------------------------
    def _on_map(self, msg: OccupancyGrid) -> None:
        if self.has_map and self.params.first_map_only:
            return
        info = msg.info
        data = np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width)
        geometry = GridGeometry(info.resolution, info.origin.position.x, info.origin.position.y,
                                info.width, info.height)
        with self.lock:
            self.map_frame = msg.header.frame_id or 'map'
            self.costmap.set_map(data, geometry)
            self.unknown_mask = data == -1 if not self.costmap.cfg.rolling_window else None
            self.has_map = True
        rospy.loginfo(f'{self.name}: received a {info.width} X {info.height} map at {info.resolution:.3f} m/pix')

    def _observations(self) -> List[Observation]:
        out: List[Observation] = []
        for src in self.sources:
            convert = self._cloud_observation if src.params.data_type == 'PointCloud2' else self._scan_observation
            for msg in src.new_scans():
                try:
                    obs = convert(src.params, msg)
                except ValueError as exc:          # a malformed cloud: skip it
                    rospy.logwarn_throttle(5.0, f'{self.name}: {src.params.name}: dropping a message: {exc}')
                    obs = []
                if obs is None:
                    if (rospy.Time.now() - msg.header.stamp).to_sec() < 1.0:
                        break                      # tf not there yet: retry this message next cycle
                else:
                    out += obs
                src.next_stamp = msg.header.stamp + rospy.Duration(0, 1)
        return out

    def _scan_observation(self, params: SourceParams, scan: LaserScan) -> Optional[List[Observation]]:
        """The scan as an observation in the costmap frame; None while its tf is not available."""
        found = self.tf.lookup(self.costmap.cfg.global_frame, params.sensor_frame or scan.header.frame_id,
                               scan.header.stamp)
        if found is None:
            return None
        sensor, z = found
        return [scan_to_observation(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                                    scan.range_max, sensor, z, params.layer)]

    def _cloud_observation(self, params: SourceParams, cloud: PointCloud2) -> Optional[List[Observation]]:
        """The cloud transformed at its stamp into the costmap frame; None while its tf is not available."""
        frame = self.costmap.cfg.global_frame
        found = self.tf.lookup_matrix(frame, cloud.header.frame_id, cloud.header.stamp)
        origin = None
        if found is not None and params.sensor_frame and params.sensor_frame != cloud.header.frame_id:
            sensor = self.tf.lookup_matrix(frame, params.sensor_frame, cloud.header.stamp)
            if sensor is None:
                return None
            origin = sensor[1]
        if found is None:
            return None
        points = cloud_xyz(cloud.data, cloud.width, cloud.height, cloud.point_step, cloud.row_step,
                           {f.name: (f.offset, f.datatype) for f in cloud.fields}, cloud.is_bigendian)
        return [cloud_to_observation(points, found[0], found[1], params.layer, self.costmap.cfg.resolution, origin)]

    def sleep(self) -> None:
        """Dormant (a retired migration instance kept for a quick wake-up): the observation sources are
        unsubscribed, so no sensor data crosses to this instance and none is processed, and the obstacles are
        forgotten (stale by the time it wakes); the update loop is paused by ``active``. The map subscription
        stays (latched, silent)."""
        for src in self.sources:
            src.subscriber.sub.unregister()
        with self.lock:
            self.costmap.clear_obstacles()

    def wake(self) -> None:
        """Subscribe to the observation sources again (after :meth:`sleep`)."""
        fresh = []
        for src in self.sources:
            new = _Source(src.params)
            new.max_obstacle_height = src.max_obstacle_height      # as configured, not as reconfigured
            fresh.append(new)
        self.sources = fresh

    def sensors_current(self, warn: bool = True) -> bool:
        """costmap_2d's ``isCurrent``: every source with an expected rate sent a scan recently (``warn``: say
        which one did not, at most every 5 s)."""
        now = rospy.Time.now()
        for src in self.sources:
            rate = src.params.expected_update_rate
            if rate <= 0:
                continue
            last = src.last_time()
            if last is None or (now - last).to_sec() > rate:
                if warn:
                    rospy.logwarn_throttle(5.0, f'The {src.params.name} observation buffer has not been updated '
                                                f'for {(now - last).to_sec() if last else float("inf"):.2f} seconds, '
                                                f'and it should be updated every {rate:.2f} seconds.')
                return False
        return True

    # -- pose -------------------------------------------------------------------------------------
    def robot_pose(self) -> Optional[Pose2D]:
        cfg = self.costmap.cfg
        found = self.tf.lookup(cfg.global_frame, cfg.robot_base_frame, tolerance=cfg.transform_tolerance)
        return found[0] if found else None

    def frame_to_map(self) -> Optional[Pose2D]:
        """Pose of this costmap's frame in the static map's frame."""
        if self.costmap.cfg.global_frame == self.map_frame:
            return IDENTITY
        found = self.tf.lookup(self.map_frame, self.costmap.cfg.global_frame)
        return found[0] if found else None

    # -- update loop --------------------------------------------------------------------------------
    def update(self) -> bool:
        """One update cycle (also called directly by tests/bench); False if the pose is unknown."""
        robot = self.robot_pose()
        if robot is None:
            return False
        if self.costmap.cfg.static_layer is not None and not self.has_map:
            rospy.loginfo_throttle(10.0, f'{self.name}: waiting for the map on {self.params.map_topic}')
        frame_to_map = self.frame_to_map() if self.has_map else IDENTITY
        obs = self._observations()
        with self.lock:
            t0 = time.perf_counter()
            self.costmap.update(robot, obs, frame_to_map or IDENTITY, stamp=rospy.get_time())
            self.update_time = time.perf_counter() - t0
            self.robot = robot
        return True

    def _update_loop(self) -> None:
        while not rospy.is_shutdown():
            freq = self.costmap.cfg.update_frequency
            try:
                if not self.active():
                    time.sleep(0.1)        # paused: a wall-clock nap (rospy.sleep in sim time wakes the thread
                    continue               # at every /clock message: 0.025 CPU for a dormant move_base)
                self.update()
                if self.costmap_pub is not None and self.publishing():
                    self._publish()
                rospy.sleep(1.0 / freq if freq > 0 else 0.1)
            except rospy.ROSInterruptException:
                return
            except rospy.exceptions.ROSTimeMovedBackwardsException:
                continue
            except Exception as exc:   # keep the costmap alive; report what went wrong
                if rospy.core.is_shutdown_requested():
                    return             # e.g. the costmap published onto a topic the shutdown closed
                rospy.logerr_throttle(5.0, f'{self.name}: update failed: {exc!r}')
                rospy.sleep(0.1)

    def _publish(self) -> None:
        cfg = self.costmap.cfg
        now = rospy.get_time()
        robot = self.robot
        stamp = rospy.Time.now()
        if robot is not None:
            self.footprint_pub.publish(footprint_msg(self.footprint, robot, cfg.global_frame, stamp))
        if cfg.publish_frequency <= 0 or now < self._next_publish:
            return
        self._next_publish = now + 1.0 / cfg.publish_frequency
        with self.lock:
            g = self.costmap.geometry
            values = occupancy_values(self.costmap.costs)
        if self.params.always_send_full_costmap or self._published_geometry != g or self._published_values is None:
            msg = OccupancyGrid()
            msg.header.frame_id = cfg.global_frame
            msg.header.stamp = stamp
            msg.info.map_load_time = stamp
            msg.info.resolution = g.resolution
            msg.info.width, msg.info.height = g.width, g.height
            msg.info.origin.position.x, msg.info.origin.position.y = g.origin_x, g.origin_y
            msg.info.origin.orientation.w = 1.0
            msg.data = values.ravel().tobytes()
            self.costmap_pub.publish(msg)
        else:
            changed = values != self._published_values
            if changed.any():
                rows = np.flatnonzero(changed.any(axis=1))
                cols = np.flatnonzero(changed.any(axis=0))
                r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
                up = OccupancyGridUpdate()
                up.header.frame_id = cfg.global_frame
                up.header.stamp = stamp
                up.x, up.y, up.width, up.height = int(c0), int(r0), int(c1 - c0), int(r1 - r0)
                up.data = values[r0:r1, c0:c1].ravel().tobytes()
                self.updates_pub.publish(up)
        self._published_geometry = g
        self._published_values = values

    # -- planner / controller queries -----------------------------------------------------------------
    def planning_grid(self, static_only: bool = False) -> PlanningGrid:
        with self.lock:
            costs = self.costmap.static_costs if static_only else self.costmap.costs
            return PlanningGrid(costs, self.costmap.geometry, self.unknown_mask, self.costmap.cfg.inscribed_radius)

    def in_collision(self, pose: Pose2D) -> bool:
        with self.lock:
            return int(self.costmap.cost_at(pose.x, pose.y)) >= INSCRIBED_INFLATED_OBSTACLE

    def clear(self, robot: Optional[Pose2D] = None, reset_distance: Optional[float] = None,
              invert: bool = False, layer_names: Optional[List[str]] = None) -> None:
        """Reset the obstacle layer (if named in ``layer_names``), wholly or around ``robot``."""
        names = [p for p, k in self.params.plugins if k == 'obstacle']
        if layer_names is not None and not any(n in layer_names for n in names):
            return
        with self.lock:
            self.costmap.clear_obstacles(robot, reset_distance, invert)

    # -- dynamic_reconfigure ----------------------------------------------------------------------------
    def _replace(self, **changes) -> None:
        with self.lock:
            self.costmap.reconfigure(dataclasses.replace(self.costmap.cfg, **changes))

    def _on_costmap_cfg(self, config: Dict, level: int) -> Dict:
        try:
            footprint = parse_footprint(config['footprint'], rospy.resolve_name(self.ns))
        except Exception as exc:   # a bad footprint string must not kill the server
            rospy.logwarn(f'{self.name}: ignoring footprint {config["footprint"]!r}: {exc}')
            footprint = []
        radius = max((float(np.hypot(x, y)) for x, y in footprint), default=config['robot_radius'])
        self.footprint = footprint or circle_footprint(radius)
        self._replace(transform_tolerance=config['transform_tolerance'],
                      update_frequency=config['update_frequency'], publish_frequency=config['publish_frequency'],
                      width=config['width'] if self.costmap.cfg.rolling_window else self.costmap.cfg.width,
                      height=config['height'] if self.costmap.cfg.rolling_window else self.costmap.cfg.height,
                      resolution=config['resolution'] if config['resolution'] > 0 else self.costmap.cfg.resolution,
                      origin_x=config['origin_x'], origin_y=config['origin_y'], robot_radius=radius,
                      footprint_padding=config['footprint_padding'])
        return config

    def _on_static_cfg(self, config: Dict, level: int) -> Dict:
        if self.costmap.cfg.static_layer is not None:
            self._replace(static_layer=dataclasses.replace(self.costmap.cfg.static_layer, enabled=config['enabled']))
        return config

    def _on_obstacle_cfg(self, config: Dict, level: int) -> Dict:
        layer = self.costmap.cfg.obstacle_layer
        if layer is not None:
            self._replace(obstacle_layer=dataclasses.replace(
                layer, enabled=config['enabled'], footprint_clearing_enabled=config['footprint_clearing_enabled'],
                max_obstacle_height=config['max_obstacle_height'], combination_method=config['combination_method']))
            for src in self.sources:
                src.params.layer = dataclasses.replace(
                    src.params.layer, max_obstacle_height=min(src.max_obstacle_height, config['max_obstacle_height']))
        return config

    def _on_inflation_cfg(self, config: Dict, level: int) -> Dict:
        layer = self.costmap.cfg.inflation_layer
        if layer is not None:
            self._replace(inflation_layer=dataclasses.replace(
                layer, enabled=config['enabled'], cost_scaling_factor=config['cost_scaling_factor'],
                inflation_radius=config['inflation_radius'], inflate_unknown=config['inflate_unknown']))
        return config
