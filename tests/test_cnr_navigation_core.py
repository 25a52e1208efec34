"""Navigation cores without a master: inflation costs, planning on small grids, the DWA controller, point clouds."""
import math
import os
from dataclasses import replace

import numpy as np
import pytest

from cnr_navigation.core.costmap import (INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, GridGeometry, LayeredCostmap,
                                         inflate, inflation_cost_of_distance, scan_to_observation)
from cnr_navigation.core.dwa import DWAController
from cnr_navigation.core.geometry import Pose2D, quaternion_to_matrix
from cnr_navigation.core.param_files import read_config
from cnr_navigation.core.planner import GlobalPlanner, PlanningError, PlanningGrid
from cnr_navigation.core.pointcloud import cloud_to_observation, cloud_xyz

RES = 0.05
#: the TurtleBot navigation configuration (config/navigation), as the move_base node reads it
NAV = read_config(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config'))
LOCAL = NAV.local_costmap.config


def inflation(**values):
    return replace(LOCAL.inflation_layer, **values)


def turtlebot_planner():
    return GlobalPlanner(replace(NAV.planner, allow_unknown=True))


def test_inflation_cost_formula():
    k, r_ins, r_inf = 5.0, 0.2, 0.5
    d = np.array([0.0, 0.1, 0.2, 0.25, 0.3, 0.45, 0.5, 0.55, 1.0])
    cost = inflation_cost_of_distance(d, RES, r_ins, r_inf, k)
    assert cost[0] == LETHAL_OBSTACLE
    assert cost[1] == cost[2] == INSCRIBED_INFLATED_OBSTACLE
    for i in (3, 4, 5, 6):
        assert cost[i] == math.floor(252 * math.exp(-k * (d[i] - r_ins)))
    assert cost[7] == 0 and cost[8] == 0                  # beyond ceil(r_inf / res) cells


def test_inflate_grid_around_a_lethal_cell():
    grid = np.zeros((41, 41), dtype=np.uint8)
    grid[20, 20] = LETHAL_OBSTACLE
    out = inflate(grid, RES, 0.2, inflation(inflation_radius=0.5, cost_scaling_factor=5.0))
    assert out[20, 20] == LETHAL_OBSTACLE
    assert out[20, 24] == INSCRIBED_INFLATED_OBSTACLE     # 0.20 m away
    assert out[20, 26] == math.floor(252 * math.exp(-5.0 * (0.3 - 0.2)))
    assert out[20, 31] == 0                               # 0.55 m away
    assert out[23, 24] == out[24, 23]                     # isotropic


def planning_grid(costs):
    h, w = costs.shape
    return PlanningGrid(costs=costs, geometry=GridGeometry(RES, 0.0, 0.0, w, h), inscribed_radius=0.2)


def test_plan_straight_line_on_free_grid():
    plan = turtlebot_planner().make_plan(planning_grid(np.zeros((20, 60), np.uint8)),
                                                    Pose2D(0.1, 0.5, 0.0), Pose2D(2.8, 0.5, 0.0))
    assert plan[0, :2] == pytest.approx([0.1, 0.5]) and plan[-1, :2] == pytest.approx([2.8, 0.5])
    assert np.all(np.abs(plan[:, 1] - 0.5) < RES)
    length = np.sum(np.hypot(np.diff(plan[:, 0]), np.diff(plan[:, 1])))
    assert length == pytest.approx(2.7, abs=0.1)


def test_plan_goes_around_a_wall():
    costs = np.zeros((60, 60), np.uint8)
    costs[0:45, 30] = LETHAL_OBSTACLE                      # wall with a gap at the top
    costs = inflate(costs, RES, 0.1, inflation(inflation_radius=0.3, cost_scaling_factor=5.0))
    plan = turtlebot_planner().make_plan(planning_grid(costs), Pose2D(0.5, 0.5, 0), Pose2D(2.5, 0.5, 0))
    rows = (plan[:, 1] / RES).astype(int).clip(0, 59)
    cols = (plan[:, 0] / RES).astype(int).clip(0, 59)
    assert np.all(costs[rows, cols] < INSCRIBED_INFLATED_OBSTACLE)
    assert plan[:, 1].max() > 45 * RES                    # went over the wall's end


def test_no_path_and_goal_in_obstacle_raise():
    costs = np.zeros((20, 60), np.uint8)
    costs[:, 30] = LETHAL_OBSTACLE                         # closed wall
    planner = turtlebot_planner()
    with pytest.raises(PlanningError):
        planner.make_plan(planning_grid(costs), Pose2D(0.5, 0.5, 0), Pose2D(2.5, 0.5, 0))
    with pytest.raises(PlanningError) as err:
        planner.check_goal(planning_grid(costs), Pose2D(30 * RES + 0.01, 0.5, 0))
    assert 'obstacle' in str(err.value)
    with pytest.raises(PlanningError) as err:
        planner.check_goal(planning_grid(costs), Pose2D(50.0, 0.5, 0))
    assert 'off the global costmap' in str(err.value)


def local_costmap():
    layer = replace(LOCAL.obstacle_layer, track_unknown_space=False, min_obstacle_height=0.0, max_obstacle_height=2.0)
    cfg = replace(LOCAL, global_frame='odom', rolling_window=True, width=4.0, height=4.0, robot_radius=0.2,
                  static_layer=None, obstacle_layer=layer,
                  inflation_layer=inflation(inflation_radius=0.5, cost_scaling_factor=5.0))
    return LayeredCostmap(cfg, 'local_costmap')


def test_dwa_drives_toward_the_plan_and_respects_limits():
    cm = local_costmap()
    cm.update(Pose2D(0, 0, 0), [], stamp=0.0)
    dwa = DWAController(replace(NAV.dwa, max_vel_x=0.5, max_vel_trans=0.5, max_vel_y=0.0, min_vel_y=0.0, vy_samples=1,
                                  acc_lim_x=1.0, acc_lim_theta=2.0, sim_time=1.0, vx_samples=6), 5.0)
    plan = np.stack([np.linspace(0, 3, 61), np.zeros(61), np.zeros(61)], axis=1)
    assert dwa.set_plan(plan)
    res = dwa.compute_velocity(Pose2D(0, 0, 0), (0.3, 0.0), cm)
    v, w = res.cmd
    assert 0.3 < v <= 0.5 + 1e-9 and abs(w) < 0.5
    assert v <= 0.3 + 1.0 * 0.2 + 1e-9                    # acceleration window of one 5 Hz period


def test_dwa_avoids_an_obstacle_seen_by_the_laser():
    cm = local_costmap()
    layer = cm.cfg.obstacle_layer
    ranges = np.full(640, 5.0)
    fov = math.radians(58)
    angles = -fov / 2 + np.arange(640) * fov / 639
    ranges[np.abs(angles) < 0.15] = 0.8                   # a person 0.8 m straight ahead
    obs = scan_to_observation(ranges, -fov / 2, fov / 639, 0.45, 5.0, Pose2D(0, 0, 0), 0.3, layer)
    cm.update(Pose2D(0, 0, 0), [obs], stamp=0.0)
    dwa = DWAController(replace(NAV.dwa, max_vel_x=0.5, max_vel_trans=0.5, max_vel_y=0.0, min_vel_y=0.0, vy_samples=1,
                                  sim_time=1.7, vx_samples=6, occdist_scale=0.5), 5.0)
    plan = np.stack([np.linspace(0, 3, 61), np.zeros(61), np.zeros(61)], axis=1)
    dwa.set_plan(plan)
    res = dwa.compute_velocity(Pose2D(0, 0, 0), (0.5, 0.0), cm)
    if res.cmd is not None and res.trajectory.shape[0]:
        xs, ys = res.trajectory[:, 0], res.trajectory[:, 1]
        # the chosen trajectory never enters the obstacle's lethal/inscribed cells
        costs = cm.cost_at(xs, ys)
        assert np.all(costs < INSCRIBED_INFLATED_OBSTACLE)
    else:
        assert res.mode in ('failed', 'stop')


def test_cloud_xyz_reads_offsets_padding_and_byte_order():
    pts = np.arange(18, dtype=np.float64).reshape(6, 3)                # 2 rows x 3 points
    rec = np.zeros((2, 3), dtype=np.dtype({'names': ['z', 'x', 'y', 'i'], 'formats': ['<f4', '<f4', '<f4', '<u4'],
                                           'offsets': [0, 4, 8, 12], 'itemsize': 16}))
    rec['x'], rec['y'], rec['z'] = pts[:, 0].reshape(2, 3), pts[:, 1].reshape(2, 3), pts[:, 2].reshape(2, 3)
    data = b''.join(row.tobytes() + b'\xff' * 8 for row in rec)      # row_step 56: 8 bytes of row padding
    fields = {'z': (0, 7), 'x': (4, 7), 'y': (8, 7), 'intensity': (12, 6)}
    assert np.array_equal(cloud_xyz(data, 3, 2, 16, 56, fields, False), pts)
    big = np.zeros(6, dtype=[('x', '>f8'), ('y', '>f8'), ('z', '>f8')])
    big['x'], big['y'], big['z'] = pts.T
    assert np.array_equal(cloud_xyz(big.tobytes(), 6, 1, 24, 144, {'x': (0, 8), 'y': (8, 8), 'z': (16, 8)}, True), pts)
    with pytest.raises(ValueError, match="no 'z' field"):
        cloud_xyz(data, 3, 2, 16, 56, {'x': (4, 7), 'y': (8, 7)}, False)
    with pytest.raises(ValueError, match='bytes of data'):
        cloud_xyz(data[:-1], 3, 2, 16, 56, fields, False)


#: camera frame (x forward, z up) -> optical frame (x right, y down, z forward), as the simulator's static tf
OPTICAL = quaternion_to_matrix((-0.5, 0.5, -0.5, 0.5))


def depth_source(**values):
    return replace(next(s for s in NAV.local_costmap.sources if s.name == 'depth').layer, **values)


def test_cloud_to_observation_filters_heights_and_transforms():
    """A camera 0.3 m up at (1, 2) facing +y: points (optical frame) are kept by height and moved to the costmap."""
    yaw90 = quaternion_to_matrix((0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)))
    rotation, translation = yaw90 @ OPTICAL, np.array([1.0, 2.0, 0.3])
    points = np.array([[0.0, 0.0, 2.0],          # 2 m ahead at the camera's height: marks (1, 4)
                       [0.0, -0.2, 2.0],         # same column, 0.5 m up: marks the same cell, same clearing ray
                       [0.0, 0.3, 1.5],          # the floor (z = 0): dropped
                       [0.0, -0.5, 2.0],         # 0.8 m up, above max_obstacle_height 0.6: dropped
                       [np.nan, np.nan, np.nan],  # no depth
                       [-1.0, 0.0, 3.5]])        # 3.64 m away, 1 m to the left: beyond obstacle_range, clears only
    cfg = depth_source()
    assert (cfg.min_obstacle_height, cfg.max_obstacle_height, cfg.obstacle_range, cfg.raytrace_range) == \
        (0.05, 0.6, 2.5, 3.0)                                            # config/navigation/costmap_common.yaml
    obs = cloud_to_observation(points, rotation, translation, cfg, 0.05)
    assert (obs.sensor_x, obs.sensor_y, obs.sensor_z) == (1.0, 2.0, 0.3)
    assert np.allclose(obs.mark_x, [1.0, 1.0]) and np.allclose(obs.mark_y, [4.0, 4.0])
    assert obs.clear_x.size == 2                                         # one ray per direction
    order = np.argsort(obs.clear_x)
    far = math.hypot(1.0, 3.5)
    assert np.allclose(obs.clear_x[order], [1.0 - 3.0 / far, 1.0]) and \
        np.allclose(obs.clear_y[order], [2.0 + 3.0 * 3.5 / far, 4.0])    # cut at raytrace_range
    assert list(obs.hit[order]) == [False, True]
    none = cloud_to_observation(points, rotation, translation, replace(cfg, marking=False, clearing=False), 0.05)
    assert none.mark_x.size == 0 and none.clear_x.size == 0


def test_local_costmap_marks_and_clears_with_a_depth_cloud():
    """An organised cloud of a wall 1.5 m ahead: the wall's cells become lethal, the cells before it free."""
    cm = LayeredCostmap(replace(LOCAL, obstacle_layer=replace(LOCAL.obstacle_layer, track_unknown_space=True)), 'local')
    cols, rows = np.meshgrid(np.linspace(-0.5, 0.5, 80), np.linspace(-0.4, 0.3, 60))
    depth = np.full(cols.shape, 1.5)
    cloud = np.stack([cols * depth, rows * depth, depth], axis=-1).reshape(-1, 3).astype(np.float32)
    data = cloud.tobytes()
    points = cloud_xyz(data, 80, 60, 12, 960, {'x': (0, 7), 'y': (4, 7), 'z': (8, 7)}, False)
    obs = cloud_to_observation(points, OPTICAL, np.array([0.0, 0.0, 0.287]), depth_source(), cm.cfg.resolution)
    cm.update(Pose2D(0.0, 0.0, 0.0), [obs], stamp=0.0)
    assert cm.cost_at(1.52, 0.0) == LETHAL_OBSTACLE and cm.cost_at(1.52, 0.4) == LETHAL_OBSTACLE
    assert cm.obstacles.grid[cm.geometry.world_to_cell(1.0, 0.0)] == 0            # seen free
    assert cm.obstacles.grid[cm.geometry.world_to_cell(1.0, 1.5)] == 255          # outside the view: unknown


def test_readme_parameter_tables_are_the_generated_ones(workspace):
    from cnr_navigation.core.param_docs import markdown_tables
    with open(f'{workspace}/src/cnr_navigation/README.md') as f:
        assert markdown_tables(f'{workspace}/config').strip() in f.read(), \
            'regenerate: python3 -m cnr_navigation.core.param_docs config'


def test_navigation_parameters_come_from_config_and_a_missing_one_is_named(workspace):
    from cnr_params import ConfigError
    from cnr_navigation.core.param_files import TreeReader, navigation_tree
    from cnr_navigation.core.param_reader import read_navigation_params
    tree = navigation_tree(f'{workspace}/config')
    params = read_navigation_params(TreeReader(dict(tree)), '/move_base')
    assert params.move_base.controller_frequency == 5.0 and params.dwa.sim_time == 1.0
    assert params.local_costmap.config.width == 4.0 and params.clearing_radius == 0.46
    assert params.global_costmap.map_topic == 'map' and params.local_costmap.sources[0].topic == 'scan'
    for costmap in (params.global_costmap, params.local_costmap):      # both costmaps use the Kinect's two streams
        assert [(s.name, s.data_type, s.topic) for s in costmap.sources] == \
            [('scan', 'LaserScan', 'scan'), ('depth', 'PointCloud2', 'camera/depth/points')]
    with pytest.raises(ConfigError, match="depth: data_type: unsupported 'Image'"):
        read_navigation_params(TreeReader(dict(tree, **{'/move_base/global_costmap/obstacle_layer/depth/data_type':
                                                        'Image'})), '/move_base')
    for name, message in (('/move_base/DWAPlannerROS/sim_time', '/move_base/DWAPlannerROS: sim_time: missing'),
                          ('/move_base/global_costmap/static_layer/map_topic',
                           '/move_base/global_costmap/static_layer: map_topic: missing'),
                          ('/move_base/TrajectoryPlannerROS/acc_lim_theta',
                           '/move_base/TrajectoryPlannerROS: acc_lim_theta: missing'),
                          ('/move_base/global_costmap/obstacle_layer/obstacle_range',
                           'obstacle_range: missing \\(searched upwards')):
        broken = {k: v for k, v in tree.items() if k != name}
        assert len(broken) == len(tree) - 1
        with pytest.raises(ConfigError, match=message):
            read_navigation_params(TreeReader(broken), '/move_base')
