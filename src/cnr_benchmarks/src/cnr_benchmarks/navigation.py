"""Navigation benchmark: global plan across the data-center hall, one control-loop cycle, one depth frame.

    /usr/bin/python3 -m cnr_benchmarks.navigation [--out bench_results/sim/navigation.json]

Uses the TurtleBot configuration as the move_base node reads it from config/navigation (robot radius
0.20 m, inflation 0.5 m, k 5, DWA with 6 x 20 samples over 1.0 s), 640-beam scans and 80 x 60 depth clouds
(the ``depth`` source). Prints one line per figure and writes JSON.
"""
from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np

from cnr_benchmarks.cli import sim_part_parser
from cnr_benchmarks.results import WS, save_json
from cnr_navigation.core.costmap import GridGeometry, LayeredCostmap, scan_to_observation
from cnr_navigation.core.dwa import DWAController
from cnr_navigation.core.geometry import Pose2D, quaternion_to_matrix
from cnr_navigation.core.param_files import read_config
from cnr_navigation.core.planner import GlobalPlanner, PlanningGrid
from cnr_navigation.core.pointcloud import cloud_to_observation, cloud_xyz


def hall_costmap() -> LayeredCostmap:
    from cnr_maps.mapio import load_map
    grid = load_map(os.path.join(WS, 'maps', 'datacenter.yaml'))
    cm = LayeredCostmap(read_config(os.path.join(WS, 'config')).global_costmap.config, 'global_costmap')
    cm.set_map(grid.data, GridGeometry(grid.resolution, grid.origin[0], grid.origin[1], grid.width, grid.height))
    return cm


def plan_times(n: int) -> list:
    cm = hall_costmap()
    planner = GlobalPlanner(read_config(os.path.join(WS, 'config')).planner)
    grid = PlanningGrid(cm.costs, cm.geometry, None, cm.cfg.inscribed_radius)
    start, goal = Pose2D(1.0, 1.0, 0.0), Pose2D(19.0, 12.8, 0.0)     # opposite corners of the hall
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        plan = planner.make_plan(grid, start, goal)
        times.append((time.perf_counter() - t0) * 1e3)
    assert plan.shape[0] > 100
    return times


def control_times(n: int) -> list:
    nav = read_config(os.path.join(WS, 'config'))
    cfg = nav.local_costmap.config
    cm = LayeredCostmap(cfg, 'local_costmap')
    dwa = DWAController(nav.dwa, nav.move_base.controller_frequency)
    dwa.set_plan(np.stack([np.linspace(0, 10, 201), 0.3 * np.sin(np.linspace(0, 3, 201)), np.zeros(201)], axis=1))
    fov = math.radians(58.0)
    rng = np.random.default_rng(0)
    times = []
    x = 0.0
    for _ in range(n):
        ranges = 2.0 + rng.uniform(0, 2.5, 640)              # a cluttered scene inside 4.5 m
        t0 = time.perf_counter()
        pose = Pose2D(x, 0.0, 0.0)
        obs = scan_to_observation(ranges, -fov / 2, fov / 639, 0.45, 5.0, Pose2D(x - 0.087, 0.0, 0.0), 0.287,
                                  cfg.obstacle_layer)
        cm.update(pose, [obs], stamp=0.0)
        dwa.compute_velocity(pose, (0.4, 0.0), cm)
        times.append((time.perf_counter() - t0) * 1e3)
        x += 0.08
    return times


def depth_times(n: int) -> list:
    """One 80 x 60 organised cloud (float32 x, y, z, optical frame) into the local costmap: parse, transform,
    filter, mark and clear, update (what move_base does per depth frame and costmap)."""
    nav = read_config(os.path.join(WS, 'config'))
    cfg = nav.local_costmap.config
    source = next(s for s in nav.local_costmap.sources if s.data_type == 'PointCloud2')
    cm = LayeredCostmap(cfg, 'local_costmap')
    optical = quaternion_to_matrix((-0.5, 0.5, -0.5, 0.5))
    cols, rows = np.meshgrid(np.linspace(-0.54, 0.54, 80), np.linspace(-0.39, 0.39, 60))
    rng = np.random.default_rng(0)
    fields = {'x': (0, 7), 'y': (4, 7), 'z': (8, 7)}
    times = []
    x = 0.0
    for _ in range(n):
        depth = np.repeat(1.0 + rng.uniform(0, 3.0, (1, 80)), 60, axis=0)    # a cluttered scene, one wall per column
        data = np.stack([cols * depth, rows * depth, depth], axis=-1).astype(np.float32).tobytes()
        t0 = time.perf_counter()
        obs = cloud_to_observation(cloud_xyz(data, 80, 60, 12, 960, fields, False), optical,
                                   np.array([x - 0.087, 0.0, 0.287]), source.layer, cfg.resolution)
        cm.update(Pose2D(x, 0.0, 0.0), [obs], stamp=0.0)
        times.append((time.perf_counter() - t0) * 1e3)
        x += 0.08
    return times


def main() -> None:
    ap = sim_part_parser(__doc__, 'navigation.json')
    ap.add_argument('--runs', type=int, default=20)
    args = ap.parse_args()
    results = []

    def report(name, values, unit, target):
        med = statistics.median(values)
        results.append(dict(name=name, value=round(med, 3), unit=unit, target=target,
                            max=round(max(values), 3), runs=len(values)))
        print(f'{name:48s} {med:12.2f} {unit:10s} (median of {len(values)}, max {max(values):.2f}; '
              f'target {target})', flush=True)

    plan_times(1)
    report('global plan across the data-center hall', plan_times(args.runs), 'ms', '<= 150')
    control_times(3)
    report('control loop (local costmap + DWA, 640 beams)', control_times(args.runs * 10), 'ms', '<= 10')
    depth_times(3)
    report('depth frame into the local costmap (80 x 60)', depth_times(args.runs * 10), 'ms', '-')
    save_json(args.out, results)


if __name__ == '__main__':
    main()
