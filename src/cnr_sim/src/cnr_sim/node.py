"""The ``simulator`` node: ROS I/O around :class:`cnr_sim.core.world.World` (a stage_ros look-alike).

Publishes /clock, odom, base_pose_ground_truth, scan, camera/depth/points, the two battery packs (the base's,
battery_state, and the robot computer's, laptop_charge, as config/battery.yaml names them), obstacles,
collision events and tf; subscribes mobile_base/commands/velocity (through the ``~command_fence`` plugin, if
any: e.g. a managed move_base instance that does not hold the lease is ignored); services reset_positions and
teleport. Every topic, service and parameter is documented in the package README.
"""
from __future__ import annotations

import math
import socket
import threading
import time
from typing import Callable, Optional, Set
from urllib.parse import urlparse
from xmlrpc.client import ServerProxy

import numpy as np
import rospy
import tf2_ros
from geometry_msgs.msg import Pose, PoseArray, Quaternion, TransformStamped, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import BatteryState, LaserScan, PointCloud2, PointField
from std_srvs.srv import Empty, EmptyResponse

import cnr_params
from cnr_maps.mapio import load_map
from cnr_maps.pose import Pose2D, yaw_to_quaternion
from cnr_msgs.msg import BatteryEnergy, Collision
from cnr_msgs.srv import Teleport, TeleportResponse
from cnr_params.ros import private_section
from cnr_runtime import init_node
from cnr_sim.core.battery import BatteryModel, NetMeter, Pack, cpu_meter
from cnr_sim.core.depth_camera import POINT_STEP
from cnr_sim.core import plugins
from cnr_sim.core.plugins import CommandGate, CpuUsage
from cnr_sim.core.world import World
from cnr_sim.params import SimulatorParams, read_params


def yaw_quaternion(yaw: float) -> Quaternion:
    """geometry_msgs/Quaternion of a yaw [rad] (the tuple from :func:`cnr_maps.pose.yaw_to_quaternion`)."""
    return Quaternion(*yaw_to_quaternion(yaw))


def transform(stamp: rospy.Time, parent: str, child: str, x: float, y: float, yaw: float,
              z: float = 0.0, rotation: Optional[Quaternion] = None) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    t.transform.rotation = rotation if rotation is not None else yaw_quaternion(yaw)
    return t


#: camera frame (x forward, z up) -> optical frame (x right, y down, z forward): rpy (-pi/2, 0, -pi/2)
OPTICAL_ROTATION = Quaternion(-0.5, 0.5, -0.5, 0.5)


class RobotProcesses:
    """PIDs of the nodes registered on this master that run on this host (slave API getPid)."""

    def __init__(self, caller_id: str) -> None:
        self.caller_id = caller_id
        self._local = self._local_addresses()
        self._resolved = {}

    @staticmethod
    def _local_addresses() -> Set[str]:
        import psutil
        addrs = {'localhost', socket.gethostname(), socket.getfqdn()}
        for entries in psutil.net_if_addrs().values():
            for a in entries:
                if a.family in (socket.AF_INET, socket.AF_INET6):
                    addrs.add(a.address.split('%')[0])
        return addrs

    def _is_local(self, host: str) -> bool:
        if host in self._local or host.startswith('127.'):
            return True
        if host not in self._resolved:
            try:
                self._resolved[host] = socket.gethostbyname(host)
            except OSError:
                self._resolved[host] = ''
        ip = self._resolved[host]
        return ip in self._local or ip.startswith('127.')

    def pids(self) -> Set[int]:
        import rosgraph
        master = rosgraph.Master(self.caller_id)
        pubs, subs, srvs = master.getSystemState()
        nodes = {n for _, names in pubs + subs + srvs for n in names}
        out = set()
        for name in nodes:
            try:
                uri = master.lookupNode(name)
                if not self._is_local(urlparse(uri).hostname or ''):
                    continue
                code, _, pid = ServerProxy(uri).getPid(self.caller_id)
                if code == 1:
                    out.add(int(pid))
            except Exception:  # a node that went away between the two calls
                continue
        return out


class SimulatorNode:
    """The simulator.

    Args:
        params: its parameters.
        fence: decides whose velocity commands move the base (None: everyone's).
        cpu_usage: reads a cgroup's CPU seconds (called with ``~battery/cpu_cgroup`` if one is named).
    """

    def __init__(self, params: SimulatorParams, fence: Optional[CommandGate] = None,
                 cpu_usage: Optional[Callable[[str], CpuUsage]] = None) -> None:
        self.p = params
        grid = load_map(params.map_file)
        self.grid = grid
        self.battery = BatteryModel(params.battery)
        try:
            self.world = World(grid, params.limits, params.laser, params.world, params.initial_pose,
                               params.obstacles, self.battery, np.random.default_rng(params.seed or None),
                               params.depth if params.depth_enabled else None)
        except ValueError as exc:
            raise cnr_params.ConfigError(rospy.get_name(), 'initial_pose', str(exc))
        self.lock = threading.Lock()
        ns = rospy.get_name()
        # 100: a catch-up burst after a stall (up to 0.5 s of wall time, see run()) is ~20 clocks at 2x; a
        # shorter queue dropped one under CI load and a node saw a 0.1 s jump of sim time
        self.clock_pub = rospy.Publisher('/clock', Clock, queue_size=100)
        self.next_clock = 0.0           # sim time of the next /clock message (~clock_frequency)
        self.odom_pub = rospy.Publisher('odom', Odometry, queue_size=10)
        self.gt_pub = rospy.Publisher('base_pose_ground_truth', Odometry, queue_size=10)
        self.scan_pub = rospy.Publisher('scan', LaserScan, queue_size=5)
        self.depth_pub = rospy.Publisher('camera/depth/points', PointCloud2, queue_size=2) \
            if params.depth_enabled else None
        self.pack_pubs = [(pack, rospy.Publisher(pack.config.topic, BatteryState, queue_size=2))
                          for pack in self.battery.packs]
        self.energy_pub = rospy.Publisher('battery/energy', BatteryEnergy, queue_size=2)
        self.collision_pub = rospy.Publisher('mobile_base/events/collision', Collision, queue_size=10)
        self.obstacles_pub = rospy.Publisher('obstacles', PoseArray, queue_size=2)
        self.tf = tf2_ros.TransformBroadcaster()
        self.static_tf = tf2_ros.StaticTransformBroadcaster()
        self.fence = fence
        rospy.Subscriber('mobile_base/commands/velocity', Twist, self._on_cmd, queue_size=5)
        rospy.Service('reset_positions', Empty, self._on_reset)
        rospy.Service('teleport', Teleport, self._on_teleport)
        self._scan_msg = self._scan_template()
        self._cloud_msg = self._cloud_template()
        self._procs = RobotProcesses(ns)
        self._cpu = cpu_meter(params.battery_cpu_cgroup, cpu_usage) if params.battery_enabled else None
        self._net = NetMeter(params.battery_interface) if params.battery_enabled else None
        self._next_battery = 0.0
        self.rtf_achieved = 0.0

    # -- callbacks -----------------------------------------------------------------------------
    def _on_cmd(self, msg: Twist) -> None:
        header = getattr(msg, '_connection_header', None)
        if self.fence is not None and not self.fence.accept(header):
            rospy.logwarn_throttle(5.0, self.fence.refusal(header))
            return
        v, w = msg.linear.x, msg.angular.z
        if not (math.isfinite(v) and math.isfinite(w)):
            rospy.logwarn_throttle(5.0, f'rejected velocity command with non-finite values ({v}, {w})')
            return
        with self.lock:
            self.world.command(v, w)

    def _on_reset(self, _req) -> EmptyResponse:
        with self.lock:
            self.world.reset()
        rospy.loginfo('reset to the start pose')
        return EmptyResponse()

    def _on_teleport(self, req) -> TeleportResponse:
        pose = Pose2D(req.pose.x, req.pose.y, req.pose.theta)
        with self.lock:
            problem = self.world.teleport(pose, req.reset_odometry)
        if problem:
            rospy.logwarn(f'teleport to ({pose.x:.3f}, {pose.y:.3f}, {pose.yaw:.3f}) refused: {problem}')
            return TeleportResponse(False, problem)
        return TeleportResponse(True, 'ok')

    # -- messages ------------------------------------------------------------------------------
    def _scan_template(self) -> LaserScan:
        c = self.p.laser
        m = LaserScan()
        m.header.frame_id = self.p.laser_frame
        m.angle_min = c.angle_min
        m.angle_max = c.angle_min + c.angle_increment * (c.beams - 1)
        m.angle_increment = c.angle_increment
        m.time_increment = 0.0
        m.scan_time = 1.0 / c.rate
        m.range_min = c.min_range
        m.range_max = c.max_range
        return m

    def _cloud_template(self) -> PointCloud2:
        c = self.p.depth
        m = PointCloud2()
        m.header.frame_id = self.p.depth_frame
        m.height, m.width = c.height, c.width
        m.fields = [PointField(name, 4 * i, PointField.FLOAT32, 1) for i, name in enumerate('xyz')]
        m.is_bigendian = False
        m.point_step = POINT_STEP
        m.row_step = POINT_STEP * c.width
        m.is_dense = False                # pixels without a valid depth are NaN
        return m

    def _odometry(self, stamp, frame: str, pose: Pose2D) -> Odometry:
        o = Odometry()
        o.header.stamp = stamp
        o.header.frame_id = frame
        o.child_frame_id = self.p.footprint_frame
        o.pose.pose.position.x, o.pose.pose.position.y = pose.x, pose.y
        o.pose.pose.orientation = yaw_quaternion(pose.yaw)
        o.twist.twist.linear.x = self.world.base.v
        o.twist.twist.angular.z = self.world.base.w
        return o

    def publish_static(self) -> None:
        p = self.p
        stamp = rospy.Time.from_sec(max(self.world.time, 1e-3))
        static = [transform(stamp, p.footprint_frame, p.base_frame, 0.0, 0.0, 0.0, p.base_height),
                  transform(stamp, p.base_frame, p.laser_frame, p.laser.offset_x, p.laser.offset_y, 0.0,
                            p.laser_offset_z - p.base_height)]
        if p.depth_enabled:
            static.append(transform(stamp, p.laser_frame, p.depth_frame, 0.0, 0.0, 0.0, 0.0, OPTICAL_ROTATION))
        self.static_tf.sendTransform(static)

    def publish(self, collision) -> None:
        w, p = self.world, self.p
        stamp = rospy.Time.from_sec(w.time)
        if w.time + 1e-9 >= self.next_clock:
            self.clock_pub.publish(Clock(stamp))
            period = 1.0 / p.clock_frequency if p.clock_frequency > 0 else 0.0
            self.next_clock = max(self.next_clock + period, w.time) if period else w.time
        odom = self._odometry(stamp, p.odom_frame, w.odom)
        self.odom_pub.publish(odom)
        self.gt_pub.publish(self._odometry(stamp, p.map_frame, w.pose))
        tfs = [transform(stamp, p.odom_frame, p.footprint_frame, w.odom.x, w.odom.y, w.odom.yaw)]
        if p.publish_map_to_odom:
            m2o = w.map_to_odom()
            tfs.append(transform(stamp, p.map_frame, p.odom_frame, m2o.x, m2o.y, m2o.yaw))
        self.tf.sendTransform(tfs)
        if collision is not None:
            c = Collision()
            c.header.stamp = rospy.Time.from_sec(collision.time)
            c.header.frame_id = p.map_frame
            c.pose.x, c.pose.y, c.pose.theta = collision.pose.x, collision.pose.y, collision.pose.yaw
            c.speed = collision.speed
            c.obstacle = collision.obstacle
            self.collision_pub.publish(c)
            rospy.logwarn_throttle(2.0, f'collision with {collision.obstacle} at '
                                        f'({collision.pose.x:.2f}, {collision.pose.y:.2f}); base stopped')
        if w.scan_due():
            ranges = w.scan()
            msg = self._scan_msg
            msg.header.stamp = stamp
            msg.ranges = ranges.tolist()
            self.scan_pub.publish(msg)
            if w.obstacles:
                centres, _ = w.obstacle_positions()
                pa = PoseArray()
                pa.header.stamp = stamp
                pa.header.frame_id = p.map_frame
                pa.poses = [Pose(position=_point(x, y), orientation=yaw_quaternion(0.0)) for x, y in centres]
                self.obstacles_pub.publish(pa)
        if w.depth_due():
            cloud = self._cloud_msg
            cloud.header.stamp = stamp
            cloud.data = w.depth_frame().tobytes()
            self.depth_pub.publish(cloud)
        if w.time + 1e-9 >= self._next_battery:
            self._next_battery = w.time + 1.0 / p.battery_rate
            for pack, pub in self.pack_pubs:
                pub.publish(self._battery_msg(stamp, pack))
            self.energy_pub.publish(self._energy_msg(stamp))

    @staticmethod
    def _battery_msg(stamp, b: Pack) -> BatteryState:
        c = b.config
        m = BatteryState()
        m.header.stamp = stamp
        m.voltage = b.voltage
        m.current = b.current
        m.charge = b.charge_ah
        m.capacity = c.capacity_ah
        m.design_capacity = c.capacity_ah
        m.percentage = b.percentage / 100.0
        m.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
        m.power_supply_health = BatteryState.POWER_SUPPLY_HEALTH_GOOD
        m.power_supply_technology = BatteryState.POWER_SUPPLY_TECHNOLOGY_LION
        m.present = True
        m.location = c.location
        m.serial_number = ' '.join(f'{k}={v:.1f}J' for k, v in b.breakdown.items())
        return m

    def _energy_msg(self, stamp) -> BatteryEnergy:
        b, e = self.battery, self.battery.energy
        return BatteryEnergy(header=rospy.Header(stamp=stamp), idle=e.idle, motors=e.motors, cpu=e.cpu,
                             radio=e.radio, total=e.total, cpu_seconds=b.cpu_seconds, radio_bytes=b.radio_bytes)

    # -- loops ---------------------------------------------------------------------------------
    def _measure_loop(self) -> None:
        """Measure the robot's CPU time and radio bytes (wall-clock period) and feed the battery."""
        period = self.p.battery_measure_period
        last_refresh = -math.inf
        last_sim = self.world.time
        while not rospy.is_shutdown():
            now = time.monotonic()
            if self._cpu.needs_pids and now - last_refresh > 5.0:
                last_refresh = now
                try:
                    self._cpu.set_pids(self._procs.pids())
                except Exception as exc:
                    rospy.logwarn_throttle(30.0, f'cannot list the robot processes on the master: {exc}')
            cpu = self._cpu.sample()
            if self._cpu.problem:
                rospy.logwarn_throttle(30.0, f'battery: CPU time not charged: {self._cpu.problem}')
            net = self._net.sample()
            with self.lock:
                sim_dt = self.world.time - last_sim
                last_sim = self.world.time
                self.battery.add_work(cpu, net, sim_dt)
            time.sleep(period)

    def run(self) -> None:
        self.publish_static()
        if self._cpu is not None:
            threading.Thread(target=self._measure_loop, name='battery_meter', daemon=True).start()
        rtf = self.p.real_time_factor
        dt = self.p.world.step
        wall0, sim0 = time.monotonic(), self.world.time
        report_wall, report_sim = wall0, sim0
        rospy.loginfo(f'simulating {self.grid.source} at '
                      f'{"as fast as possible" if rtf == 0 else f"{rtf:g}x real time"}')
        while not rospy.is_shutdown():
            with self.lock:
                event = self.world.step()
                self.publish(event)     # at shutdown, may raise on a closed topic: see cnr_runtime.init_node
                sim = self.world.time
            if rtf > 0:
                target = wall0 + (sim - sim0) / rtf
                lag = target - time.monotonic()
                if lag > 0:
                    time.sleep(lag)
                elif lag < -0.5:      # cannot keep up: restart the schedule instead of bursting
                    rospy.logwarn_throttle(10.0, f'cannot keep {rtf:g}x real time')
                    wall0, sim0 = time.monotonic(), sim
            now = time.monotonic()
            if now - report_wall >= 5.0:
                self.rtf_achieved = (sim - report_sim) / (now - report_wall)
                rospy.logdebug(f'achieved real-time factor {self.rtf_achieved:.2f}')
                report_wall, report_sim = now, sim


def _point(x: float, y: float):
    from geometry_msgs.msg import Point
    return Point(float(x), float(y), 0.0)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('simulator')
    section = private_section('~')
    params = read_params(section)
    fence = _plugin(section, 'command_fence', params.command_fence)
    cpu_usage = None
    if params.battery_enabled and params.battery_cpu_cgroup:
        cpu_usage = _plugin(section.section('battery'), 'cpu_usage', params.battery_cpu_usage)
    node = SimulatorNode(params, fence() if fence is not None else None, cpu_usage)
    node.run()


def _plugin(section, key: str, spec: str) -> Optional[Callable]:
    """The factory a plugin parameter names (None for ''); a config error naming the parameter if it cannot be
    loaded."""
    if not spec:
        return None
    try:
        return plugins.load(spec)
    except ValueError as exc:
        raise section.error(key, str(exc))
