"""Simulator benchmark: core speed without ROS, time per laser scan and per depth frame, real-time factor with ROS I/O.

    /usr/bin/python3 -m cnr_benchmarks.sim [--out bench_results/sim/sim.json] [--sim-seconds 600]

Prints one line per figure and writes them as JSON (name, value, unit, target).
"""
from __future__ import annotations

import os
import time

import numpy as np

from cnr_benchmarks.cli import sim_part_parser
from cnr_benchmarks.results import WS, save_json
from cnr_harness import RosMaster, wait_until
from cnr_maps.mapio import load_map
from cnr_maps.pose import Pose2D
from cnr_sim.core.world import World
from cnr_sim.params import config_section, read_depth_camera, read_laser, read_limits, read_world


def turtlebot_world(map_yaml: str, start: Pose2D) -> World:
    """The simulated TurtleBot 2 as config/ describes it (robot.yaml, laser.yaml, depth_camera.yaml)."""
    sim = config_section(os.path.join(WS, 'config'))
    return World(load_map(map_yaml), read_limits(sim), read_laser(sim), read_world(sim), start,
                 depth=read_depth_camera(sim))


def core_rtf(map_yaml: str, start: Pose2D, sim_seconds: float) -> tuple:
    """Real-time multiple of the world (50 Hz steps, 640-beam laser at 10 Hz, 80 x 60 depth at 7.4 Hz, a driving
    robot)."""
    world = turtlebot_world(map_yaml, start)
    world.scan()                                     # compile / warm up
    steps = int(sim_seconds / world.config.step)
    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    scans = 0
    for i in range(steps):
        if i % 25 == 0:
            world.command(float(rng.uniform(0.0, 0.5)), float(rng.uniform(-1.0, 1.0)))
        world.step()
        if world.scan_due():
            world.scan()
            scans += 1
        if world.depth_due():
            world.depth_frame()
    wall = time.perf_counter() - t0
    return sim_seconds / wall, steps / wall, scans


def sensor_time(map_yaml: str, start: Pose2D, sensor: str, n: int = 2000) -> float:
    """Milliseconds per call of the world's ``sensor`` (``scan`` or ``depth_frame``), after a warm-up call."""
    render = getattr(turtlebot_world(map_yaml, start), sensor)
    render()
    t0 = time.perf_counter()
    for _ in range(n):
        render()
    return (time.perf_counter() - t0) / n * 1e3


def ros_rtf(wall_seconds: float) -> float:
    """Run the simulator node as fast as possible on a private master; /clock advance per wall second."""
    master = RosMaster(use_sim_time=True, caller='/sim_bench')
    try:
        sim = master.roslaunch('cnr_sim', 'simulator.launch', 'real_time_factor:=0')
        os.environ.update(master.env)
        import rospy
        from rosgraph_msgs.msg import Clock
        rospy.init_node('sim_bench', anonymous=True, disable_signals=True)
        latest = {'t': 0.0}
        rospy.Subscriber('/clock', Clock, lambda m: latest.__setitem__('t', m.clock.to_sec()), queue_size=1)
        wait_until(lambda: latest['t'] >= 1.0, 60, '1 s of simulated time on /clock', sim)
        t_sim0, t_wall0 = latest['t'], time.monotonic()
        time.sleep(wall_seconds)                     # the measurement window, not a synchronisation
        return (latest['t'] - t_sim0) / (time.monotonic() - t_wall0)
    finally:
        master.stop()


def main() -> None:
    ap = sim_part_parser(__doc__, 'sim.json')
    ap.add_argument('--sim-seconds', type=float, default=600.0, help='simulated seconds per core run')
    ap.add_argument('--ros-seconds', type=float, default=20.0, help='wall seconds of the ROS I/O run')
    args = ap.parse_args()
    results = []

    def report(name, value, unit, target):
        results.append(dict(name=name, value=round(value, 3), unit=unit, target=target))
        print(f'{name:48s} {value:12.2f} {unit:10s} (target {target})', flush=True)

    for label, yaml, start in (('corridor', 'corridor.yaml', Pose2D(0.5, 0.0, 0.0)),
                               ('datacenter', 'datacenter.yaml', Pose2D(1.0, 1.0, 0.0))):
        path = os.path.join(WS, 'maps', yaml)
        rtf, steps, _ = core_rtf(path, start, args.sim_seconds)
        report(f'sim core real-time multiple ({label})', rtf, 'x', '>= 1000')
        report(f'sim core steps per second ({label})', steps, 'steps/s', '-')
        report(f'time per 640-beam scan ({label})', sensor_time(path, start, 'scan'), 'ms', '-')
        report(f'time per 80x60 depth frame ({label})', sensor_time(path, start, 'depth_frame'), 'ms', '-')
    report('sim with ROS I/O, as fast as possible', ros_rtf(args.ros_seconds), 'x real time', '>= 20')
    save_json(args.out, results)


if __name__ == '__main__':
    main()
