"""What both nodes share on the ROS side: stamps, the relay's connection header, raw-bytes message classes."""
from __future__ import annotations

from typing import Type

import rospy
import roslib.message

# added by the receiver to the connection header of its output topic; the sender ignores (and counts) input
# from such a publisher, so a relayed message can never be relayed again, whatever the topic names or the
# bridge's allow-lists are
RELAY_HEADER = 'cnr_store_forward_stream'


def ros_time(stamp_ns: int) -> rospy.Time:
    return rospy.Time(secs=stamp_ns // 1_000_000_000, nsecs=stamp_ns % 1_000_000_000)


def raw_message_class(type_name: str, md5sum: str) -> Type[rospy.AnyMsg]:
    """A message class that publishes already serialized bytes as ``type_name``.

    The definition (for tools such as rostopic and rosbag) comes from the local message package if it is
    installed and has the same MD5 sum, else it is empty (typed subscribers do not need it).
    """
    definition = ''
    try:
        local = roslib.message.get_message_class(type_name)
    except (ValueError, ImportError):
        local = None
    if local is not None and local._md5sum == md5sum:
        definition = local._full_text
    return type('StoreForwardRaw', (rospy.AnyMsg,), {
        '__slots__': (), '_type': type_name, '_md5sum': md5sum, '_full_text': definition, '_has_header': False})


def raw_message(cls: Type[rospy.AnyMsg], data: bytes) -> rospy.AnyMsg:
    msg = cls()
    msg._buff = data
    return msg
