"""move_base with the depth camera as its only obstacle source, on a real master: the Kinect's cloud marks walls."""
import os
import shutil

import numpy as np
import pytest
import yaml

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


@pytest.fixture(scope='module')
def depth_only_robot(ros, workspace, tmp_path_factory):
    """The simulated TurtleBot facing the corridor's upper wall (1.09 m ahead), move_base without the scan source."""
    import actionlib
    from move_base_msgs.msg import MoveBaseAction
    config = str(tmp_path_factory.mktemp('depth_only') / 'config')
    shutil.copytree(os.path.join(workspace, 'config'), config)
    common = os.path.join(config, 'navigation', 'costmap_common.yaml')
    with open(common) as f:
        data = yaml.safe_load(f)
    data['obstacle_layer']['observation_sources'] = 'depth'
    data['always_send_full_costmap'] = True                 # each published costmap is complete
    with open(common, 'w') as f:
        yaml.safe_dump(data, f)
    proc = ros.master.roslaunch('cnr_bringup', 'robot.launch', f'config_dir:={config}', 'real_time_factor:=2.0',
                                'x:=4.0', 'y:=0.0', 'a:=1.5707963')
    client = actionlib.SimpleActionClient('move_base', MoveBaseAction)

    def ready():
        assert proc.alive(), proc.output()[-3000:]
        return not rospy.Time.now().is_zero() and client.wait_for_server(rospy.Duration(0.5))
    wait_until(ready, 120, 'the move_base action server')
    yield proc
    proc.stop()


def lethal_cells(msg):
    """World (x, y) of the lethal cells of a nav_msgs/OccupancyGrid."""
    info = msg.info
    grid = np.asarray(msg.data, dtype=np.int8)
    rows, cols = np.nonzero(grid.reshape(info.height, info.width) == 100)
    return (info.origin.position.x + (cols + 0.5) * info.resolution,
            info.origin.position.y + (rows + 0.5) * info.resolution)


def test_move_base_subscribes_the_cloud_not_the_scan(ros, depth_only_robot):
    def subscribers(topic):
        _, subs, _ = ros.master.call('getSystemState')
        return next((nodes for name, nodes in subs if name == topic), [])
    wait_until(lambda: '/move_base' in subscribers('/camera/depth/points'), 30, 'move_base on camera/depth/points')
    assert '/move_base' not in subscribers('/scan')


def test_wall_seen_only_by_the_depth_camera_is_lethal_in_the_local_costmap(depth_only_robot):
    from nav_msgs.msg import OccupancyGrid
    latest = {}
    sub = rospy.Subscriber('move_base/local_costmap/costmap', OccupancyGrid,
                           lambda m: latest.__setitem__('msg', m), queue_size=1)

    def wall_marked():      # the local costmap is in odom, whose origin is the start pose: the wall is at x = 1.0
        msg = latest.get('msg')
        if msg is None:
            return False
        x, y = lethal_cells(msg)
        on_wall = (x > 1.0) & (x < 1.05) & (np.abs(y) < 0.4)
        return on_wall.sum() >= 10 and (x, y)
    x, y = wait_until(wall_marked, 60, 'lethal cells on the wall 1 m ahead in the local costmap')
    sub.unregister()
    # every mark lies on the wall the camera faces (none from the scan, which move_base does not use here)
    assert np.all((x > 1.0) & (x < 1.1)), sorted(set(np.round(x, 3)))
