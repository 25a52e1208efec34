"""The simulator with a real rosmaster: rates, depth cloud, tf, watchdog, collisions, services, bad input."""
import math
import os
import subprocess
import threading

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


class Recorder:
    """Keeps every message of a topic."""

    def __init__(self, topic, msg_type):
        self.msgs = []
        self.lock = threading.Lock()
        self.sub = rospy.Subscriber(topic, msg_type, self._cb, queue_size=200)

    def _cb(self, msg):
        with self.lock:
            self.msgs.append(msg)

    def since(self, t):
        with self.lock:
            return [m for m in self.msgs if m.header.stamp.to_sec() >= t]

    def last(self):
        with self.lock:
            return self.msgs[-1] if self.msgs else None


@pytest.fixture(scope='module')
def sim(ros, workspace):
    from nav_msgs.msg import Odometry
    proc = ros.master.roslaunch('cnr_sim', 'simulator.launch', 'real_time_factor:=2.0', 'x:=0.5', 'y:=0.0')
    gt = Recorder('base_pose_ground_truth', Odometry)
    wait_until(lambda: gt.last() is not None or not proc.alive(), 90, 'ground truth from the simulator')
    assert proc.alive(), proc.output()[-2000:]
    yield proc
    gt.sub.unregister()
    proc.stop()


def sim_now():
    return rospy.Time.now().to_sec()


def teleport(x, y, yaw):
    from cnr_msgs.srv import Teleport
    from geometry_msgs.msg import Pose2D
    rospy.wait_for_service('teleport', 30)
    return rospy.ServiceProxy('teleport', Teleport)(Pose2D(x, y, yaw), False)


def test_scan_and_odom_rates_in_sim_time(sim):
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import LaserScan
    scans, odoms = Recorder('scan', LaserScan), Recorder('odom', Odometry)
    t0 = sim_now()
    wait_until(lambda: sim_now() > t0 + 4.0, 60, '4 s of sim time')
    s, o = scans.since(t0 + 1.0), odoms.since(t0 + 1.0)
    scans.sub.unregister(), odoms.sub.unregister()
    span = lambda m: m[-1].header.stamp.to_sec() - m[0].header.stamp.to_sec()
    assert (len(s) - 1) / span(s) == pytest.approx(10.0, rel=0.05)
    assert (len(o) - 1) / span(o) == pytest.approx(50.0, rel=0.05)
    scan = s[-1]
    assert len(scan.ranges) == 640 and scan.header.frame_id == 'camera_depth_frame'
    assert math.degrees(scan.angle_max - scan.angle_min) == pytest.approx(58.0, abs=0.01)
    assert scan.range_min == pytest.approx(0.45)
    assert o[-1].header.frame_id == 'odom' and o[-1].child_frame_id == 'base_footprint'


def test_clock_is_published_at_its_configured_frequency(sim):
    """/clock at the first step at or after every 1/clock_frequency of sim time (config/simulator.yaml), while
    odom keeps every step."""
    import yaml
    from rosgraph_msgs.msg import Clock
    config = os.path.join(os.path.dirname(__file__), '..', 'config')
    with open(os.path.join(config, 'simulator.yaml')) as f:
        frequency = yaml.safe_load(f)['clock_frequency']
    with open(os.path.join(config, 'robot.yaml')) as f:
        step = yaml.safe_load(f)['step']
    stamps, lock = [], threading.Lock()

    def on_clock(msg):
        with lock:
            stamps.append(msg.clock.to_sec())
    sub = rospy.Subscriber('/clock', Clock, on_clock, queue_size=100)
    wait_until(lambda: len(stamps) > 2 * frequency, 60, f'{2 * frequency} /clock messages')
    sub.unregister()
    with lock:
        gaps = [b - a for a, b in zip(stamps[1:], stamps[2:])]    # the first may follow a message lost to connecting
    bad = [(i, g) for i, g in enumerate(gaps) if abs(g - 1.0 / frequency) >= step + 1e-6]
    assert len(gaps) >= frequency and not bad, f'gaps off 1/{frequency:g} s by a step or more (index, gap): {bad}'
    assert sum(gaps) / len(gaps) == pytest.approx(1.0 / frequency, abs=step / len(gaps) + 1e-6)   # no drift


def test_depth_cloud_rate_size_and_frame(sim):
    """camera/depth/points: 80 x 60 organised float32 x, y, z at 7.4 Hz (sim time), 3.42 Mbit/s on the wire."""
    import io
    import tf2_ros
    from sensor_msgs.msg import PointCloud2
    clouds = Recorder('camera/depth/points', PointCloud2)
    buf = tf2_ros.Buffer()
    listener = tf2_ros.TransformListener(buf)
    t0 = sim_now()
    wait_until(lambda: sim_now() > t0 + 6.0, 60, '6 s of sim time')
    c = clouds.since(t0 + 1.0)
    clouds.sub.unregister()
    span = c[-1].header.stamp.to_sec() - c[0].header.stamp.to_sec()
    assert (len(c) - 1) / span == pytest.approx(7.4, rel=0.05)
    m = c[-1]
    assert (m.width, m.height, m.point_step, m.row_step, len(m.data)) == (80, 60, 12, 960, 57600)
    assert [(f.name, f.offset, f.datatype) for f in m.fields] == [('x', 0, 7), ('y', 4, 7), ('z', 8, 7)]
    assert m.header.frame_id == 'camera_depth_optical_frame' and not m.is_dense
    wire = io.BytesIO()
    m.serialize(wire)
    assert (len(wire.getvalue()) + 4) * 8 * 7.4 / 1e6 == pytest.approx(3.42, abs=0.01)   # + TCPROS length prefix
    t = wait_until(lambda: buf.can_transform('base_footprint', 'camera_depth_optical_frame', rospy.Time(0)) and
                   buf.lookup_transform('base_footprint', 'camera_depth_optical_frame', rospy.Time(0)), 30,
                   'tf base_footprint -> camera_depth_optical_frame')
    listener.unregister()
    assert t.transform.translation.z == pytest.approx(0.287, abs=1e-6)
    q = t.transform.rotation
    assert (q.x, q.y, q.z, q.w) == pytest.approx((-0.5, 0.5, -0.5, 0.5))


def test_tf_chain(sim):
    import tf2_ros
    buf = tf2_ros.Buffer()
    listener = tf2_ros.TransformListener(buf)

    def lookup():
        try:
            return buf.lookup_transform('map', 'camera_depth_frame', rospy.Time(0))
        except tf2_ros.TransformException:
            return None
    t = wait_until(lookup, 30, 'tf map -> camera_depth_frame')
    listener.unregister()
    assert t.transform.translation.z == pytest.approx(0.287, abs=1e-6)
    for parent, child in (('map', 'odom'), ('odom', 'base_footprint'), ('base_footprint', 'base_link')):
        assert buf.can_transform(parent, child, rospy.Time(0))


def test_static_map_service(sim):
    from nav_msgs.srv import GetMap
    rospy.wait_for_service('static_map', 30)
    grid = rospy.ServiceProxy('static_map', GetMap)().map
    assert (grid.info.width, grid.info.height) == (840, 760)
    assert grid.info.origin.position.x == pytest.approx(-29.8)


def test_base_stops_when_commands_stop_and_nan_is_ignored(sim):
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    assert teleport(0.5, 0.0, 0.0).success
    pub = rospy.Publisher('mobile_base/commands/velocity', Twist, queue_size=1)
    wait_until(lambda: pub.get_num_connections() > 0, 30, 'simulator subscribed to velocity')
    nan = Twist()
    nan.linear.x = float('nan')
    pub.publish(nan)
    gt = Recorder('base_pose_ground_truth', Odometry)
    cmd = Twist()
    cmd.linear.x = 0.3
    t_end = sim_now() + 2.0
    while sim_now() < t_end:
        pub.publish(cmd)
        rospy.sleep(0.1)
    last_cmd = sim_now()
    assert gt.last().twist.twist.linear.x == pytest.approx(0.3, abs=0.01)
    wait_until(lambda: sim_now() > last_cmd + 2.0, 30, '2 s of sim time without commands')
    stopped = [m for m in gt.since(last_cmd) if m.twist.twist.linear.x == 0.0]
    gt.sub.unregister()
    pub.unregister()
    assert stopped, 'the base did not stop'
    # stops within the 0.6 s watchdog (+ command latency) plus the deceleration 0.3 / 1.0 s
    assert stopped[0].header.stamp.to_sec() - last_cmd < 0.6 + 0.3 + 0.4


def test_collision_stops_the_robot(sim):
    from cnr_msgs.msg import Collision
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    assert teleport(4.0, 0.0, math.pi / 2).success             # facing the upper wall (y = 1.0)
    events = Recorder('mobile_base/events/collision', Collision)
    gt = Recorder('base_pose_ground_truth', Odometry)
    pub = rospy.Publisher('mobile_base/commands/velocity', Twist, queue_size=1)
    wait_until(lambda: pub.get_num_connections() > 0, 30, 'simulator subscribed to velocity')
    cmd = Twist()
    cmd.linear.x = 0.5
    t_end = sim_now() + 5.0
    while sim_now() < t_end and not events.msgs:
        pub.publish(cmd)
        rospy.sleep(0.1)
    wait_until(lambda: events.msgs, 10, 'a collision event')
    for _ in range(10):
        pub.publish(cmd)
        rospy.sleep(0.1)
    ev = events.msgs[0]
    assert ev.obstacle == 'map'
    assert max(m.pose.pose.position.y for m in gt.msgs) < 1.0 - 0.178 + 1e-6
    assert gt.last().twist.twist.linear.x == 0.0
    events.sub.unregister(), gt.sub.unregister(), pub.unregister()


def test_teleport_rejects_outside_map(sim):
    r = teleport(100.0, 0.0, 0.0)
    assert not r.success and 'outside the map' in r.message
    assert teleport(0.5, 0.0, 0.0).success


def run_simulator(ros, workspace, name, **values):
    """``rosrun cnr_sim simulator`` with config/ loaded as simulator.launch loads it, changed by ``values``."""
    from cnr_sim.params import config_section
    data = config_section(os.path.join(workspace, 'config'), real_time_factor=1.0, initial_pose=[0.5, 0.0, 0.0],
                          **values).data
    for key in [k for k, v in values.items() if v is None]:
        del data[key]
    ros.master.call('setParam', f'/{name}', data)
    try:
        return subprocess.run(['rosrun', 'cnr_sim', 'simulator', f'__name:={name}'], env=ros.master.env,
                              capture_output=True, text=True, timeout=60)
    finally:
        ros.master.call('deleteParam', f'/{name}')


def test_bad_map_file_exits_2_with_one_line(ros, tmp_path, workspace):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('image: none.pgm\nresolution: -1\norigin: [0, 0, 0]\nnegate: 0\n'
                   'occupied_thresh: 0.65\nfree_thresh: 0.196\n')
    r = run_simulator(ros, workspace, 'bad_sim', map_file=str(bad))
    assert r.returncode == 2
    lines = [l for l in r.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and 'bad.yaml' in lines[0] and 'resolution' in lines[0], r.stderr


def test_missing_parameter_exits_2_naming_it(ros, workspace):
    r = run_simulator(ros, workspace, 'incomplete_sim', map_file=os.path.join(workspace, 'maps', 'corridor.yaml'),
                      seed=None)
    assert r.returncode == 2
    lines = [l for l in r.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and '/incomplete_sim: seed: missing' in lines[0], r.stderr
