"""Simulator cores without a master: ray casting, depth camera, kinematics and limits, collisions, battery."""
import dataclasses
import math
import os

import numpy as np
import pytest

from cnr_params import ConfigError, Section
from cnr_sim.core.battery import BatteryConfig, BatteryModel, CpuMeter
from cnr_sim.core.depth_camera import DepthCamera
from cnr_maps.mapio import OccupancyMap
from cnr_maps.pose import Pose2D
from cnr_sim.core.kinematics import DiffDrive, integrate
from cnr_sim.core.laser import FakeLaser
from cnr_sim.core.obstacles import MovingObstacle, obstacles_from_config
from cnr_sim.core.raycast import cast_rays, circle_hits
from cnr_sim.core.world import World
from cnr_sim.params import config_section, read_depth_camera, read_laser, read_limits, read_world

RES = 0.05
#: the simulator's private namespace as simulator.launch loads it from config/
SIM = config_section(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config'))


def box_map(size=200, wall_col=150):
    """A 10 m x 10 m free square with a wall at x = wall_col * RES and a border."""
    data = np.zeros((size, size), dtype=np.int8)
    data[:, wall_col:] = 100
    data[0, :] = data[-1, :] = data[:, 0] = 100
    return OccupancyMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def test_raycast_matches_analytic_distances():
    m = box_map()
    obstacle = m.data >= 50
    wall_x = 150 * RES
    x, y = 2.013, 5.021
    angles = np.radians(np.linspace(-30, 30, 61))
    out = np.empty_like(angles)
    cast_rays(obstacle, RES, 0.0, 0.0, x, y, angles, 50.0, out)
    expected = (wall_x - x) / np.cos(angles)
    assert np.allclose(out, expected, atol=1e-9)


def test_raycast_max_range_and_leaving_map():
    data = np.zeros((20, 20), dtype=np.int8)
    out = np.empty(2)
    cast_rays(data >= 50, RES, 0.0, 0.0, 0.5, 0.5, np.array([0.0, math.pi / 2]), 0.2, out)
    assert np.all(np.isinf(out))


def test_circle_hits_analytic():
    d = circle_hits(0.0, 0.0, np.array([0.0, math.pi / 2, math.atan2(0.1, 2.0)]), np.array([[2.0, 0.0]]), np.array([0.5]))
    assert d[0] == pytest.approx(1.5)
    assert math.isinf(d[1])
    assert d[2] < 2.0


def test_fake_laser_conventions():
    m = box_map()
    cfg = dataclasses.replace(read_laser(SIM), offset_x=0.0, offset_y=0.0, max_range=5.0)
    laser = FakeLaser(cfg, m.data >= 50, RES, (0, 0))
    assert cfg.beams == 640 and cfg.angle_increment == pytest.approx(math.radians(58) / 639)
    ranges = laser.scan(5.0, 5.0, 0.0)                      # wall 2.5 m ahead
    assert ranges[320] == pytest.approx(2.5 / math.cos(cfg.relative_angles[320]), abs=1e-9)
    ranges = laser.scan(1.0, 5.0, math.pi)                  # border 1 m behind... no: facing the x=0 border
    assert np.nanmin(ranges) > 0.9
    far = laser.scan(5.0, 5.0, math.pi)                     # facing the border 5 m away -> beyond 5 m -> max_range
    assert np.all(far[np.abs(cfg.relative_angles) > 0.2] == cfg.max_range)
    close = laser.scan(7.3, 5.0, 0.0)                       # wall 0.2 m ahead: below min_range -> NaN
    assert np.isnan(close[320])
    with_person = laser.scan(5.0, 5.0, 0.0, np.array([[6.0, 5.0]]), np.array([0.25]))
    assert with_person[320] == pytest.approx(0.75, abs=1e-6)


def test_depth_camera_sees_a_wall_at_its_distance():
    """A wall square to the optical axis: every wall pixel has the same depth; lower rows see the floor."""
    cfg = read_depth_camera(SIM)                                        # config/depth_camera.yaml (Kinect)
    assert (cfg.width, cfg.height, cfg.min_range, cfg.max_range) == (80, 60, 0.45, 4.0)
    cam = DepthCamera(cfg, box_map(wall_col=60).data >= 50, RES, (0, 0))
    frame = cam.frame(1.013, 5.021, 0.0)                                # wall x = 3.0: 1.987 m ahead
    assert frame.shape == (60, 80, 3) and frame.dtype == np.float32
    assert len(frame.tobytes()) == cfg.frame_bytes == 80 * 60 * 12     # x, y, z float32 per point
    x, y, z = frame[..., 0], frame[..., 1], frame[..., 2]              # optical frame: right, down, forward
    floor = np.isclose(y, cfg.mount_height, atol=1e-6)                  # pixels seeing the floor (z = 0)
    wall = ~floor
    assert floor.any() and wall.any() and not np.isnan(frame).any()
    assert np.allclose(z[wall], 1.987, atol=1e-5)
    # the floor is seen below the wall's foot: floor pixels are the bottom rows, nearer than the wall
    assert np.all(z[floor] < 1.987) and floor[-1].all() and not floor[0].any()
    # field of view: pixel centres span (n - 1) / n of the image; their edges span 57 x 43 deg
    half_h = np.arctan(np.abs(x[wall] / z[wall]).max()) * 2
    assert math.degrees(half_h) == pytest.approx(2 * math.degrees(math.atan(math.tan(math.radians(28.5)) * 79 / 80)),
                                                 abs=1e-3)
    top = -y[0, 0] / z[0, 0]                                             # tan of the top row's elevation
    assert math.degrees(2 * math.atan(top * 60 / 59)) == pytest.approx(43.0, abs=1e-3)
    assert np.isnan(cam.frame(2.8, 5.0, 0.0)[..., 2][:20]).all()        # wall 0.2 m ahead: below min_range
    far = DepthCamera(cfg, box_map().data >= 50, RES, (0, 0)).frame(7.0, 5.0, math.pi)
    assert np.isnan(far[:30]).all() and not np.isnan(far[-1]).any()    # border 7 m away: no depth; floor seen
    person = cam.frame(1.013, 5.0, 0.0, np.array([[2.0, 5.0]]), np.array([0.25]))
    assert person[20, 40, 2] == pytest.approx(2.0 - 0.25 - 1.013, abs=0.01)


def test_depth_frames_at_the_configured_rate():
    w = make_world(depth=read_depth_camera(SIM))                        # 7.4 Hz, 50 Hz steps
    frames = []
    while w.time < 100.0:
        w.step()
        if w.depth_due():
            frames.append(w.time)
            assert w.depth_frame().shape == (60, 80, 3)
    assert len(frames) == pytest.approx(740, abs=1)
    assert np.diff(frames).max() <= 1 / 7.4 + 0.02 + 1e-9
    assert not make_world().depth_due()                                 # no camera configured


def test_depth_camera_parameters():
    from cnr_sim.params import read_params
    data = dict(SIM.data, map_file='corridor.yaml', real_time_factor=1.0, initial_pose=[0.5, 0.0, 0.0])
    p = read_params(Section(data, '/simulator'))
    assert p.depth_enabled and p.depth_frame == 'camera_depth_optical_frame'
    assert p.depth.mount_height == 0.287                                # the laser's (the Kinect's) height
    for key in ('rate', 'enabled', 'fov_v_deg'):
        depth = {k: v for k, v in data['depth_camera'].items() if k != key}
        with pytest.raises(ConfigError, match=f'/simulator: depth_camera.{key}: missing'):
            read_params(Section(dict(data, depth_camera=depth), '/simulator'))
    with pytest.raises(ConfigError, match='depth_camera.frame_id: must differ'):
        read_params(Section(dict(data, depth_camera=dict(data['depth_camera'], frame_id='camera_depth_frame')),
                            '/simulator'))


def test_velocity_limits_acceleration_and_watchdog():
    base = DiffDrive(read_limits(SIM))
    base.command(5.0, -10.0, now=0.0)
    assert base.cmd_v == 0.70 and base.cmd_w == pytest.approx(-math.pi)
    v, w = base.update(0.0, 0.02)
    assert v == pytest.approx(0.02) and w == pytest.approx(-0.04)      # 1.0 m/s^2 and 2.0 rad/s^2
    t = 0.0
    while t < 0.55:
        t += 0.02
        v, w = base.update(t, 0.02)
    assert v > 0.5
    for _ in range(100):                                                # no command for > 0.6 s
        t += 0.02
        v, w = base.update(t, 0.02)
    assert v == 0.0 and w == 0.0
    with pytest.raises(ValueError):
        base.command(float('nan'), 0.0, now=t)


def test_integrate_exact_arc():
    p = integrate(Pose2D(0, 0, 0), 1.0, math.pi / 2, 1.0)              # quarter circle of radius 2/pi
    r = 2 / math.pi
    assert (p.x, p.y, p.yaw) == pytest.approx((r, r, math.pi / 2))


def make_world(**kw):
    return World(box_map(), read_limits(SIM), read_laser(SIM), read_world(SIM), Pose2D(5.0, 5.0, 0.0), **kw)


def test_collision_stalls_and_reports_once():
    w = make_world()
    events = []
    for i in range(500):
        w.command(0.5, 0.0)
        e = w.step()
        if e:
            events.append(e)
    assert len(events) == 1 and events[0].obstacle == 'map'
    assert w.base.v == 0.0
    assert w.pose.x < 150 * RES - 0.178 + 1e-9                        # never inside the wall
    for _ in range(100):                                               # backing away is allowed
        w.command(-0.3, 0.0)
        w.step()
    assert w.pose.x < 7.0 and not w.in_contact


def test_moving_obstacle_blocks_robot():
    person = MovingObstacle('person', np.array([[6.0, 5.0], [6.0, 5.0001]]), speed=0.1, radius=0.25, loop=False,
                            start_delay=0.0)
    w = make_world(obstacles=[person])
    hit = None
    for _ in range(300):
        w.command(0.5, 0.0)
        hit = w.step() or hit
    assert hit is not None and hit.obstacle == 'person'
    assert w.pose.x < 6.0 - 0.25 - 0.178 + 1e-9


def test_teleport_refuses_bad_poses():
    w = make_world()
    assert w.teleport(Pose2D(100.0, 0.0, 0.0)) == 'outside the map'
    assert 'collision' in w.teleport(Pose2D(7.6, 5.0, 0.0))
    assert w.teleport(Pose2D(float('nan'), 5.0, 0.0)) == 'not finite'
    assert w.teleport(Pose2D(3.0, 3.0, 1.0)) == ''
    assert (w.pose.x, w.pose.y) == (3.0, 3.0)
    w.reset()
    assert (w.pose.x, w.pose.y, w.odom.x) == (5.0, 5.0, 0.0)


def test_perfect_localization_map_to_odom():
    w = make_world()
    for _ in range(100):
        w.command(0.3, 0.4)
        w.step()
    gt = w.map_to_odom().compose(w.odom)
    assert (gt.x, gt.y, gt.yaw) == pytest.approx((w.pose.x, w.pose.y, w.pose.yaw))


def test_battery_reacts_to_motion_cpu_and_radio():
    cfg = BatteryConfig.from_section(SIM.section('battery'))
    idle, moving, working = BatteryModel(cfg), BatteryModel(cfg), BatteryModel(cfg)
    for _ in range(500):
        idle.step(0.02, 0.0, 0.0, 0.0, 0.0)
        moving.step(0.02, 0.5, 0.5, 0.0, 0.0)
        working.step(0.02, 0.0, 0.0, 0.0, 0.0)
    working.add_work(cpu_seconds=2.0, bytes_transferred=10e6, interval=10.0)
    assert idle.energy.total == pytest.approx((cfg.base_idle_power + cfg.laptop_idle_power) * 10.0)
    assert moving.energy.motors > 0 and moving.base.percentage < idle.base.percentage
    assert working.energy.cpu == pytest.approx(2.0 * cfg.cpu_full_load_power / cfg.cpu_capacity)
    assert working.energy.radio == pytest.approx(10e6 * cfg.radio_joules_per_byte)
    assert working.computer.percentage < idle.computer.percentage
    assert 13.2 <= idle.base.voltage <= 16.5 and 9.0 <= idle.computer.voltage <= 12.6


def test_a_capped_robot_pays_the_full_load_power_for_its_limit():
    """Under the testbed's cap (0.33 CPU) a robot busy all the time uses 0.33 CPU-s per second and must draw the
    netbook's full-load power, not a third of it."""
    sec = SIM.section('battery')
    cfg = BatteryConfig.from_section(Section(dict(sec.data, cpu_capacity=1 / 3), sec.source))
    b = BatteryModel(cfg)
    b.add_work(cpu_seconds=10.0 / 3, bytes_transferred=0, interval=10.0)
    assert b.energy.cpu == pytest.approx(10.0 * cfg.cpu_full_load_power)
    with pytest.raises(ConfigError, match='cpu_capacity'):
        BatteryConfig.from_section(Section(dict(sec.data, cpu_capacity=0.0), sec.source))


def test_battery_config_from_repository_file(workspace):
    sec = Section.from_file(f'{workspace}/config/battery.yaml').section('battery')
    cfg = BatteryConfig.from_section(sec)
    assert cfg.base_pack.capacity_ah == 2.2 and cfg.base_pack.nominal_voltage == 14.8
    assert cfg.computer_pack.capacity_ah == 5.2 and cfg.computer_pack.nominal_voltage == 10.8
    with pytest.raises(ConfigError):
        BatteryConfig.from_section(Section({'capacity_ah': -1.0}, 'battery.yaml'))
    del sec.data['mass']
    with pytest.raises(ConfigError, match='mass: missing'):
        BatteryConfig.from_section(sec)


def test_simulator_parameters_have_no_defaults_in_code():
    """Every simulator parameter comes from config/ (or the launch file); a missing one is named."""
    from cnr_sim.params import read_params
    launch = dict(map_file='corridor.yaml', real_time_factor=1.0, initial_pose=[0.5, 0.0, 0.0])
    data = dict(SIM.data, **launch)
    assert read_params(Section(data, '/simulator')).limits.max_linear == 0.70     # config/robot.yaml
    for key in ('map_frame', 'seed', 'real_time_factor', 'enable_obstacles'):
        with pytest.raises(ConfigError, match=f'/simulator: {key}: missing'):
            read_params(Section({k: v for k, v in data.items() if k != key}, '/simulator'))
    base = {k: v for k, v in data['base'].items() if k != 'max_linear'}
    with pytest.raises(ConfigError, match='base.max_linear: missing'):
        read_params(Section(dict(data, base=base), '/simulator'))


def test_cpu_meter_measures_this_process():
    import os
    meter = CpuMeter()
    meter.set_pids([os.getpid()])
    meter.sample()
    x = 0
    for i in range(2_000_000):
        x += i
    assert meter.sample() > 0.01


def test_obstacles_config_errors():
    with pytest.raises(ConfigError) as err:
        obstacles_from_config(Section({'obstacles': [{'waypoints': [[0, 0]], 'speed': 1, 'radius': 0.2}]}, 'o.yaml'))
    assert 'waypoints' in str(err.value)
    good = {'name': 'p', 'waypoints': [[0, 0], [1, 1]], 'speed': 1, 'radius': 0.2, 'loop': False, 'start_delay': 0}
    assert len(obstacles_from_config(Section({'obstacles': [good]}, 'o.yaml'))) == 1
    with pytest.raises(ConfigError, match='speed'):
        obstacles_from_config(Section({'obstacles': [dict(good, speed=0)]}, 'o.yaml'))
    for key in ('name', 'loop', 'start_delay'):
        with pytest.raises(ConfigError, match=f'{key}: missing'):
            obstacles_from_config(Section({'obstacles': [{k: v for k, v in good.items() if k != key}]}, 'o.yaml'))
