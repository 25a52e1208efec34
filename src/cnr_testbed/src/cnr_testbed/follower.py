"""``testbed.sh follow``: set the link's conditions from the robot's position through a link-quality map.

A thin ROS node (``link_map_follower``) on the robot's master: subscribes ``base_pose_ground_truth``
(nav_msgs/Odometry) and, whenever the robot enters another region of the map (``config/link_map_*.yaml``),
sets the map's direction(s) of the emulated link to that region's conditions (dead zone = outage).
"""
from __future__ import annotations

from cnr_testbed.core.config import load_link_map


def follow(testbed, map_path: str) -> None:
    import rospy
    from nav_msgs.msg import Odometry
    link_map = load_link_map(map_path)
    rospy.init_node('link_map_follower', anonymous=True)
    state = {'region': None}

    def on_pose(msg: Odometry) -> None:
        p = msg.pose.pose.position
        name, cond = link_map.conditions_at(p.x, p.y)
        if name != state['region']:
            state['region'] = name
            testbed.set(link_map.direction, delay=cond.delay, jitter=cond.jitter, loss=cond.loss, rate=cond.rate,
                        outage=cond.outage)
            rospy.loginfo(f'robot at ({p.x:.1f}, {p.y:.1f}) entered {name} ({link_map.direction}): delay {cond.delay:g} ms, '
                          f'loss {cond.loss:g}, rate {cond.rate:g} Mbit/s' + (', OUTAGE' if cond.outage else ''))

    rospy.Subscriber('base_pose_ground_truth', Odometry, on_pose, queue_size=1)
    rospy.spin()
