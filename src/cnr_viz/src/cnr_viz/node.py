"""``viz_markers``: the mission's markers for rviz (thin node over :mod:`cnr_viz.core.scene`).

Listens to the mapcells, the merged measurements, mfg's search state and hotspot, the global goal, the robot's
pose, migration_manager's placement and network_monitor's profile; publishes the whole view as one
``visualization_msgs/MarkerArray`` on ``~markers`` at ``viz/rate`` (wall), deleting markers that went away.
"""
from __future__ import annotations

import math
import threading
import time
from typing import List, Tuple

import rospy
from geometry_msgs.msg import Point, PoseStamped, Quaternion
from nav_msgs.msg import Odometry
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

import cnr_params
from cnr_bringup.placement import load_catalog
from cnr_maps.grid import MapcellGrid
from cnr_msgs.msg import CellStates, Hotspot, MergedMeasurement, NetworkProfile, Placement, SearchState
from cnr_params import ConfigError
from cnr_params.ros import private_section
from cnr_runtime import init_node
from cnr_testbed.core.config import load_link_map
from cnr_viz.core.scene import ColorScale, MarkerSpec, Scene, VizConfig, build, link_zones, stale_keys
from mfg.core.detector import DetectorConfig

ONE_MASTER = 'one_master'


def to_marker(spec: MarkerSpec, frame_id: str, stamp: rospy.Time) -> Marker:
    m = Marker()
    m.header.frame_id, m.header.stamp = frame_id, stamp
    m.ns, m.id, m.type, m.action = spec.ns, spec.id, getattr(Marker, spec.type), Marker.ADD
    m.pose.position = Point(*spec.position)
    m.pose.orientation = Quaternion(0.0, 0.0, math.sin(spec.yaw / 2), math.cos(spec.yaw / 2))
    m.scale.x, m.scale.y, m.scale.z = spec.scale
    m.color = ColorRGBA(*spec.color)
    m.points = [Point(*p) for p in spec.points]
    m.colors = [ColorRGBA(*c) for c in spec.colors]
    m.text = spec.text
    m.frame_locked = False
    return m


class VizNode:
    def __init__(self) -> None:
        p = private_section('~')
        self.cfg = VizConfig.from_section(p)
        # the scenario's ambient and threshold, by mfg's own rules
        detector = DetectorConfig.from_section(p.section('mfg').section('threshold'))
        self.scale = ColorScale.of(self.cfg, detector.ambient, detector.ambient + detector.delta)
        placement = p.string('placement')
        self.scene = Scene()
        if placement == ONE_MASTER:
            self.scene.hosts = {m: ('robot', 0) for m in self.cfg.modules}
            self.scene.placement_source = 'one master'
        else:
            try:
                fixed = load_catalog(p.file_path('placements_file')).placement(placement)
                self.scene.hosts = {m: (fixed.host(m), 0) for m in self.cfg.modules}
                self.scene.placement_source = f'placement {fixed.name}'
            except (ConfigError, KeyError) as exc:     # the view must not end the mission: hosts shown as '?'
                rospy.logwarn(f'placement {placement!r} not shown: {exc}')
                self.scene.placement_source = f'placement {placement}'
        link_map = p.string('link_map')
        self.link_map = load_link_map(link_map) if link_map else None
        self.lock = threading.Lock()
        self.published: List[Tuple[str, int]] = []
        self.pub = rospy.Publisher('~markers', MarkerArray, queue_size=2, latch=True)
        t = self.cfg.topics
        subs = ((t['cell_states'], CellStates, self._on_cells, 1),
                (t['measurements'], MergedMeasurement, self._on_measurement, 50),
                (t['search_state'], SearchState, self._on_search, 10),
                (t['hotspot'], Hotspot, self._on_hotspot, 1),
                (t['global_goal'], PoseStamped, self._on_goal, 1),
                (t['pose'], Odometry, self._on_pose, 1),
                (t['placement'], Placement, self._on_placement, 5),
                (p.string('network_profile_topic'), NetworkProfile, self._on_profile, 5))
        for topic, kind, callback, queue in subs:
            if topic:                               # '' = not shown
                rospy.Subscriber(topic, kind, callback, queue_size=queue)

    def _on_cells(self, msg: CellStates) -> None:
        if not msg.cells:
            return
        with self.lock:
            if self.scene.grid is None:
                self.scene.grid = MapcellGrid.from_cell_states(msg)
                if self.link_map is not None:
                    g = self.scene.grid
                    regions = [(r.name, r.x_min, r.x_max, r.y_min, r.y_max, r.conditions.outage)
                               for r in self.link_map.regions]
                    self.scene.zones = tuple(link_zones(regions, self.link_map.default.outage,
                                                        (g.min_x, g.min_y, g.max_x, g.max_y)))
            self.scene.means = {c.index: c.mean_temperature for c in msg.cells if c.measurement_count}

    def _on_measurement(self, msg: MergedMeasurement) -> None:
        with self.lock:
            g = self.scene.grid
            cell = g.index_of(msg.x, msg.y) if g is not None else None   # the mapcells' own rule
            if cell is not None and math.isfinite(msg.temperature):
                self.scene.latest[cell] = msg.temperature

    def _on_search(self, msg: SearchState) -> None:
        with self.lock:
            s = self.scene
            s.mode, s.mfg_goal, s.investigation, s.checked = msg.mode, msg.goal_cell, msg.investigation_cell, \
                tuple(msg.checked)

    def _on_hotspot(self, msg: Hotspot) -> None:
        with self.lock:
            self.scene.hotspot = (msg.cell_index, msg.temperature)

    def _on_goal(self, msg: PoseStamped) -> None:
        with self.lock:
            self.scene.global_goal = (msg.pose.position.x, msg.pose.position.y)

    def _on_pose(self, msg: Odometry) -> None:
        q = msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        with self.lock:
            self.scene.robot = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw)

    def _on_placement(self, msg: Placement) -> None:
        with self.lock:
            for module, host, term in zip(msg.modules, msg.hosts, msg.terms):
                self.scene.hosts[module] = (host, term)
            self.scene.placement_source = 'migration_manager'

    def _on_profile(self, msg: NetworkProfile) -> None:
        with self.lock:
            self.scene.link = (msg.alive, msg.rtt, msg.r_bw)

    def publish(self) -> None:
        with self.lock:
            specs = build(self.scene, self.cfg, self.scale)
        stamp = rospy.Time.now()
        arr = MarkerArray()
        for ns, i in stale_keys(self.published, specs):
            arr.markers.append(Marker(ns=ns, id=i, action=Marker.DELETE))
        arr.markers += [to_marker(s, self.cfg.frame_id, stamp) for s in specs]
        self.pub.publish(arr)
        self.published = [s.key for s in specs]

    def spin(self) -> None:
        period = 1.0 / self.cfg.rate
        while not rospy.is_shutdown():      # wall-clock period: the view keeps up at any real-time factor
            self.publish()
            time.sleep(period)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('viz_markers')
    VizNode().spin()
