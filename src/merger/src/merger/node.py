"""``merger``: temperature + nearest-in-time pose -> cnr_msgs/MergedMeasurement (see the package README)."""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import message_filters
import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Temperature
from std_msgs.msg import UInt32

import cnr_params
from cnr_maps.pose import quaternion_to_yaw
from cnr_msgs.msg import MergedMeasurement
from cnr_msgs.srv import GetRecentMeasurements, GetRecentMeasurementsResponse
from cnr_params import Section
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from merger.core.nearest import NearestMerger
from merger.core.retention import Retention


@dataclass
class MergerParams:
    tolerance: float
    max_wait: float
    pose_horizon: float
    pose_topic: str
    retain_count: int
    retain_seconds: float


def read_params(p: Section) -> MergerParams:
    """No defaults in code: they live in config/merger.yaml."""
    return MergerParams(tolerance=p.number('tolerance', positive=True),
                        max_wait=p.number('max_wait', positive=True),
                        pose_horizon=p.number('pose_horizon', positive=True),
                        pose_topic=p.string('pose_topic'),
                        retain_count=p.integer('retain_count', minimum=1),
                        retain_seconds=p.number('retain_seconds', positive=True))


class MergerNode:
    def __init__(self, p: MergerParams) -> None:
        self.p = p
        self.core = NearestMerger(p.tolerance, p.max_wait, p.pose_horizon)
        self.lock = threading.Lock()
        self.pub = rospy.Publisher('merged_measurements', MergedMeasurement, queue_size=50)
        self.dropped_pub = rospy.Publisher('~dropped', UInt32, queue_size=1, latch=True)
        self.frame = 'map'
        self.retained: Retention[MergedMeasurement] = Retention(p.retain_count, p.retain_seconds)
        self.recent_srv = rospy.Service('~recent', GetRecentMeasurements, self._on_recent)
        # message_filters subscribers: the same inputs a TimeSynchronizer would take, fed to the nearest-stamp core
        self.pose_sub = message_filters.Subscriber(p.pose_topic, Odometry, queue_size=100)
        self.temp_sub = message_filters.Subscriber('temperature', Temperature, queue_size=20)
        self.pose_sub.registerCallback(self._on_pose)
        self.temp_sub.registerCallback(self._on_temperature)
        rospy.Timer(rospy.Duration(0.1), lambda _e: self._flush())

    @quiet_at_shutdown
    def _on_pose(self, msg: Odometry) -> None:
        p = msg.pose.pose
        values = (p.position.x, p.position.y, msg.header.stamp.to_sec())
        if not all(math.isfinite(v) for v in values):
            rospy.logwarn_throttle(5.0, 'ignored a pose with non-finite values')
            return
        self.frame = msg.header.frame_id or self.frame
        q = p.orientation
        yaw = quaternion_to_yaw((q.x, q.y, q.z, q.w))
        with self.lock:
            self.core.add_pose(msg.header.stamp.to_sec(), (p.position.x, p.position.y, yaw))
        self._flush()

    @quiet_at_shutdown
    def _on_temperature(self, msg: Temperature) -> None:
        if not math.isfinite(msg.temperature) or msg.header.stamp.is_zero():
            rospy.logwarn_throttle(5.0, f'ignored a measurement with temperature {msg.temperature} '
                                        f'stamped {msg.header.stamp.to_sec()}')
            return
        with self.lock:
            self.core.add_measurement(msg.header.stamp.to_sec(), msg.temperature)
        self._flush()

    def _flush(self) -> None:
        with self.lock:
            merged, dropped = self.core.process(rospy.Time.now().to_sec())
            stats = self.core.stats
        for m in merged:
            out = MergedMeasurement()
            out.header.stamp = rospy.Time.from_sec(m.measurement_stamp)
            out.header.frame_id = self.frame
            out.pose_stamp = rospy.Time.from_sec(m.pose_stamp)
            out.x, out.y, out.yaw = m.pose
            out.temperature = m.measurement
            out.stamp_difference = m.difference
            out.cell = -1                   # the merger does not know the grid: local_mapcell_manager assigns it
            with self.lock:
                self.retained.add(m.measurement_stamp, out)
            self.pub.publish(out)
        if dropped:
            self.dropped_pub.publish(UInt32(stats.dropped_no_pose))
            rospy.logwarn_throttle(10.0, f'dropped {stats.dropped_no_pose} measurement(s) with no pose within '
                                         f'{self.p.tolerance:g} s (merged {stats.merged})')

    def _on_recent(self, req) -> GetRecentMeasurementsResponse:
        with self.lock:
            items = self.retained.since(req.since.to_sec())
            oldest, evicted = self.retained.oldest, self.retained.evicted
        return GetRecentMeasurementsResponse(measurements=[m for _, m in items],
                                             oldest_retained=rospy.Time.from_sec(oldest), evicted=evicted)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('merger')
    MergerNode(read_params(private_section('~')))
    rospy.spin()
