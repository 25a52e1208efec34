"""``map_server``: map_server work-alike (latched ``map``, ``map_metadata``, ``static_map`` service).

Usage as map_server: ``rosrun cnr_sim map_server MAP.yaml`` (or the ``~map_file`` parameter).
"""
from __future__ import annotations

import sys

import rospy
from geometry_msgs.msg import Pose
from nav_msgs.msg import MapMetaData, OccupancyGrid
from nav_msgs.srv import GetMap, GetMapResponse

import cnr_params
from cnr_params.ros import private_section
from cnr_runtime import init_node
from cnr_maps.mapio import OccupancyMap, load_map
from cnr_sim.node import yaw_quaternion


def occupancy_grid(grid: OccupancyMap, frame_id: str, stamp) -> OccupancyGrid:
    """nav_msgs/OccupancyGrid of a map (row-major, row 0 at the bottom, as map_server publishes)."""
    meta = MapMetaData()
    meta.map_load_time = stamp
    meta.resolution = grid.resolution
    meta.width, meta.height = grid.width, grid.height
    meta.origin = Pose()
    meta.origin.position.x, meta.origin.position.y = grid.origin[0], grid.origin[1]
    meta.origin.orientation = yaw_quaternion(grid.origin[2])
    msg = OccupancyGrid()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.info = meta
    msg.data = grid.data.astype('int8').ravel().tolist()
    return msg


@cnr_params.exit_on_config_error
def main() -> None:
    argv = rospy.myargv(sys.argv)
    init_node('map_server')
    params = private_section('~')
    if len(argv) < 2 and 'map_file' not in params:
        raise cnr_params.ConfigError(rospy.get_name(), 'map_file', 'no map given (usage: map_server MAP.yaml)')
    path = argv[1] if len(argv) > 1 else params.string('map_file')
    grid = load_map(path)
    frame = params.string('frame_id')
    msg = occupancy_grid(grid, frame, rospy.Time.now())
    rospy.Publisher('map_metadata', MapMetaData, queue_size=1, latch=True).publish(msg.info)
    rospy.Publisher('map', OccupancyGrid, queue_size=1, latch=True).publish(msg)
    rospy.Service('static_map', GetMap, lambda _req: GetMapResponse(msg))
    rospy.loginfo(f'map {path}: {grid.width} x {grid.height} cells at {grid.resolution} m/cell')
    rospy.spin()
