"""ROS-side helpers shared by the navigation nodes: parameter reader, tf and message conversions."""
from __future__ import annotations

import collections
import math
from typing import Any, Dict, Optional, Tuple

import numpy as np
import rosgraph.masterapi
import rospy
import tf2_ros
from geometry_msgs.msg import Point32, PolygonStamped, PoseStamped, Quaternion, TransformStamped
from nav_msgs.msg import Path

from cnr_navigation.core.param_reader import missing
from cnr_navigation.core.geometry import Pose2D, quaternion_to_matrix, quaternion_to_yaw, yaw_to_quaternion


class RosParamReader:
    """:class:`cnr_navigation.core.param_reader.ParamReader` on the parameter server, one XML-RPC call each.

    ``calls`` counts the calls by kind (getParam, hasParam, searchParam, setParam).
    """

    def __init__(self) -> None:
        self.calls: Dict[str, int] = collections.Counter()

    def get(self, name: str) -> Any:
        self.calls['getParam'] += 1
        try:
            return rospy.get_param(name)
        except KeyError:
            raise missing(name) from None

    def get_optional(self, name: str) -> Optional[Any]:
        self.calls['getParam'] += 1
        return rospy.get_param(name, None)

    def has(self, name: str) -> bool:
        self.calls['hasParam'] += 1
        return bool(rospy.has_param(name))

    def search(self, namespace: str, key: str) -> Optional[str]:
        self.calls['searchParam'] += 1
        try:
            return rosgraph.masterapi.Master(namespace).searchParam(key) or None
        except rosgraph.masterapi.Error:
            return None

    def set(self, name: str, value: Any) -> None:
        self.calls['setParam'] += 1
        rospy.set_param(name, value)


# -- conversions ----------------------------------------------------------------------------------

def pose_to_2d(pose) -> Pose2D:
    """geometry_msgs/Pose -> Pose2D (yaw of the orientation)."""
    q = pose.orientation
    return Pose2D(pose.position.x, pose.position.y, quaternion_to_yaw((q.x, q.y, q.z, q.w)))


def transform_to_2d(t: TransformStamped) -> Tuple[Pose2D, float]:
    """A transform as a planar pose plus its height z [m]."""
    tr, q = t.transform.translation, t.transform.rotation
    return Pose2D(tr.x, tr.y, quaternion_to_yaw((q.x, q.y, q.z, q.w))), tr.z


def transform_to_matrix(t: TransformStamped) -> Tuple[np.ndarray, np.ndarray]:
    """A transform as a (3, 3) rotation matrix and a (3,) translation [m]."""
    tr, q = t.transform.translation, t.transform.rotation
    return quaternion_to_matrix((q.x, q.y, q.z, q.w)), np.array([tr.x, tr.y, tr.z])


def pose_stamped(pose: Pose2D, frame: str, stamp: rospy.Time) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp = stamp
    msg.pose.position.x, msg.pose.position.y = pose.x, pose.y
    msg.pose.orientation = Quaternion(*yaw_to_quaternion(pose.yaw))
    return msg


def path_msg(path: np.ndarray, frame: str, stamp: rospy.Time) -> Path:
    """(N, >=3) poses -> nav_msgs/Path."""
    msg = Path()
    msg.header.frame_id = frame
    msg.header.stamp = stamp
    msg.poses = [pose_stamped(Pose2D(float(p[0]), float(p[1]), float(p[2])), frame, stamp) for p in path]
    return msg


def footprint_msg(points, pose: Pose2D, frame: str, stamp: rospy.Time) -> PolygonStamped:
    """The footprint polygon placed at ``pose`` (as costmap_2d's published footprint)."""
    msg = PolygonStamped()
    msg.header.frame_id = frame
    msg.header.stamp = stamp
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    msg.polygon.points = [Point32(pose.x + c * x - s * y, pose.y + s * x + c * y, 0.0) for x, y in points]
    return msg


class TfHelper:
    """tf2 lookups returning planar poses; None (and a throttled warning) when unavailable."""

    def __init__(self, buffer: tf2_ros.Buffer) -> None:
        self.buffer = buffer

    def _transform(self, target: str, source: str, stamp: Optional[rospy.Time]) -> Optional[TransformStamped]:
        try:
            return self.buffer.lookup_transform(target, source, stamp or rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException) as exc:
            if stamp is None:
                rospy.logwarn_throttle(5.0, f'tf {target} <- {source} not available: {exc}')
            return None

    def lookup_matrix(self, target: str, source: str,
                      stamp: Optional[rospy.Time] = None) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """Rotation matrix and translation of ``source`` in ``target`` at ``stamp`` (latest if None)."""
        t = self._transform(target, source, stamp)
        return transform_to_matrix(t) if t is not None else None

    def lookup(self, target: str, source: str, stamp: Optional[rospy.Time] = None,
               tolerance: Optional[float] = None) -> Optional[Tuple[Pose2D, float]]:
        """Pose of ``source`` in ``target`` (and its z) at ``stamp`` (latest if None).

        With ``tolerance`` [s], a latest transform older than that is refused, as costmap_2d's
        ``getRobotPose`` does.
        """
        t = self._transform(target, source, stamp)
        if t is None:
            return None
        if tolerance is not None and tolerance > 0 and stamp is None:
            age = (rospy.Time.now() - t.header.stamp).to_sec()
            if age > tolerance and t.header.stamp != rospy.Time(0):
                rospy.logwarn_throttle(
                    5.0, f'Costmap2DROS transform timeout. Current time: {rospy.get_time():.4f}, global_pose stamp: '
                         f'{t.header.stamp.to_sec():.4f}, tolerance: {tolerance:.4f}')
                return None
        return transform_to_2d(t)
