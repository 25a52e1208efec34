"""move_base's parameter tree declared once: name, type, move_base's code default, range, description (ROS-free).

The groups mirror navigation@noetic-devel: the reconfigurable ones (:data:`RECONFIGURABLE`, one
dynamic_reconfigure server each, as the ``.cfg`` files of noetic) and those read once. Used by
:mod:`cnr_navigation.core.param_reader` (reading and validation), :mod:`cnr_navigation.reconfigure_cfg`
(the ``cfg/*.cfg`` scripts) and :mod:`cnr_navigation.core.param_docs` (the README tables).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple


@dataclass(frozen=True)
class Param:
    """One declared parameter (its value comes from config/navigation/*.yaml; there is no default in code).

    Attributes:
        name: name relative to its namespace.
        kind: 'double', 'int', 'bool' or 'str'.
        description: one line, with the unit.
        minimum / maximum: range for dynamic_reconfigure and validation (None: unbounded).
        upstream_default: reconfigurable parameters only: move_base's documented default, used solely to
            describe the server to dynamic_reconfigure (``gen.add`` needs one); the node never falls back to it.
    """

    name: str
    kind: str
    description: str
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    upstream_default: Any = None


def _d(name: str, description: str, minimum: Optional[float] = None, maximum: Optional[float] = None) -> Param:
    return Param(name, 'double', description, minimum, maximum)


def _i(name: str, description: str, minimum: Optional[float] = None, maximum: Optional[float] = None) -> Param:
    return Param(name, 'int', description, minimum, maximum)


def _b(name: str, description: str) -> Param:
    return Param(name, 'bool', description)


def _s(name: str, description: str) -> Param:
    return Param(name, 'str', description)


def _rd(name: str, upstream: float, description: str, minimum: Optional[float] = None,
        maximum: Optional[float] = None) -> Param:
    return Param(name, 'double', description, minimum, maximum, upstream)


def _ri(name: str, upstream: int, description: str, minimum: Optional[float] = None,
        maximum: Optional[float] = None) -> Param:
    return Param(name, 'int', description, minimum, maximum, upstream)


def _rb(name: str, upstream: bool, description: str) -> Param:
    return Param(name, 'bool', description, upstream_default=upstream)


def _rs(name: str, upstream: str, description: str) -> Param:
    return Param(name, 'str', description, upstream_default=upstream)


# ---------------------------------------------------------------------------------------------
# reconfigurable groups (one dynamic_reconfigure server each), as the .cfg files of noetic

MOVE_BASE_CFG: List[Param] = [
    _rs('base_global_planner', 'navfn/NavfnROS', 'The name of the plugin for the global planner to use with move_base.'),
    _rs('base_local_planner', 'base_local_planner/TrajectoryPlannerROS',
       'The name of the plugin for the local planner to use with move_base.'),
    _rd('planner_frequency', 0.0, 'The rate in Hz at which to run the planning loop.', 0, 100),
    _rd('controller_frequency', 20.0, 'The rate in Hz at which to run the control loop and send velocity commands '
       'to the base.', 0, 100),
    _rd('planner_patience', 5.0, 'How long the planner will wait in seconds in an attempt to find a valid plan '
       'before space-clearing operations are performed.', 0, 100),
    _rd('controller_patience', 15.0, 'How long the controller will wait in seconds without receiving a valid '
       'control before space-clearing operations are performed.', 0, 100),
    _ri('max_planning_retries', -1, 'How many times we will recall the planner in an attempt to find a valid plan '
       'before space-clearing operations are performed', -1, 1000),
    _rd('conservative_reset_dist', 3.0, 'The distance away from the robot in meters at which obstacles will be '
       'cleared from the costmap when attempting to clear space in the map.', 0, 50),
    _rb('recovery_behavior_enabled', True, 'Whether or not to enable the move_base recovery behaviors to attempt '
       'to clear out space.'),
    _rb('clearing_rotation_allowed', True, 'Determines whether or not the robot will attempt an in-place rotation '
       'when attempting to clear out space.'),
    _rb('shutdown_costmaps', False, 'Determines whether or not to shutdown the costmaps of the node when move_base '
       'is in an inactive state'),
    _rd('oscillation_timeout', 0.0, 'How long in seconds to allow for oscillation before executing recovery '
       'behaviors.', 0, 60),
    _rd('oscillation_distance', 0.5, 'How far in meters the robot must move to be considered not to be '
       'oscillating.', 0, 10),
    _rb('make_plan_clear_costmap', True, 'Whether or not to clear the global costmap on make_plan service call.'),
    _rb('make_plan_add_unreachable_goal', True, 'Whether or not to add the original goal to the path if it is '
       'unreachable in the make_plan service call.'),
    _rb('restore_defaults', False, 'Restore to the original configuration'),
]

COSTMAP_CFG: List[Param] = [
    _rd('transform_tolerance', 0.3, 'Specifies the delay in transform (tf) data that is tolerable in seconds.', 0, 10),
    _rd('update_frequency', 5.0, 'The frequency in Hz for the map to be updated.', 0, 100),
    _rd('publish_frequency', 0.0, 'The frequency in Hz for the map to be publish display information.', 0, 100),
    # costmap_2d declares width/height as int_t [m]; doubles here so a 4.0 m window loads as it does in C++
    _rd('width', 10.0, 'The width of the map in meters.', 0, None),
    _rd('height', 10.0, 'The height of the map in meters.', 0, None),
    _rd('resolution', 0.05, 'The resolution of the map in meters/cell.', 0, 50),
    _rd('origin_x', 0.0, 'The x origin of the map in the global frame in meters.'),
    _rd('origin_y', 0.0, 'The y origin of the map in the global frame in meters.'),
    _rs('footprint', '[]', 'The footprint of the robot specified in the robot_base_frame coordinate frame as a list '
       'in the format: [ [x1, y1], [x2, y2], ...., [xn, yn] ].'),
    _rd('robot_radius', 0.46, 'The radius of the robot in meters, this parameter should only be set for circular '
       'robots, all others should use the footprint parameter described above.', 0, 10),
    _rd('footprint_padding', 0.01, 'How much to pad (increase the size of) the footprint, in meters.'),
]

GENERIC_PLUGIN_CFG: List[Param] = [
    _rb('enabled', True, 'Whether to apply this plugin or not'),
]

OBSTACLE_PLUGIN_CFG: List[Param] = [
    _rb('enabled', True, 'Whether to apply this plugin or not'),
    _rb('footprint_clearing_enabled', True, 'Whether to clear the robot\'s footprint of lethal obstacles'),
    _rd('max_obstacle_height', 2.0, 'The maximum height of any obstacle to be inserted into the costmap in meters.',
       0, 50),
    _ri('combination_method', 1, 'Method for combining two layers (0 overwrite, 1 maximum)', 0, 2),
]

INFLATION_PLUGIN_CFG: List[Param] = [
    _rb('enabled', True, 'Whether to apply this plugin or not'),
    _rd('cost_scaling_factor', 10.0, 'A scaling factor to apply to cost values during inflation.', 0, 100),
    _rd('inflation_radius', 0.55, 'The radius in meters to which the map inflates obstacle cost values.', 0, 50),
    _rb('inflate_unknown', False, 'Whether to inflate unknown cells.'),
]

DWA_CFG: List[Param] = [
    _rd('max_vel_trans', 0.55, 'The absolute value of the maximum translational velocity for the robot in m/s', 0),
    _rd('min_vel_trans', 0.1, 'The absolute value of the minimum translational velocity for the robot in m/s', 0),
    _rd('max_vel_x', 0.55, 'The maximum x velocity for the robot in m/s'),
    _rd('min_vel_x', 0.0, 'The minimum x velocity for the robot in m/s'),
    _rd('max_vel_y', 0.1, 'The maximum y velocity for the robot in m/s'),
    _rd('min_vel_y', -0.1, 'The minimum y velocity for the robot in m/s'),
    _rd('max_vel_theta', 1.0, 'The absolute value of the maximum rotational velocity for the robot in rad/s', 0),
    _rd('min_vel_theta', 0.4, 'The absolute value of the minimum rotational velocity for the robot in rad/s', 0),
    _rd('acc_lim_x', 2.5, 'The acceleration limit of the robot in the x direction', 0, 20),
    _rd('acc_lim_y', 2.5, 'The acceleration limit of the robot in the y direction', 0, 20),
    _rd('acc_lim_theta', 3.2, 'The acceleration limit of the robot in the theta direction', 0, 20),
    _rd('acc_lim_trans', 0.1, 'The absolute value of the maximum translational acceleration for the robot in m/s^2', 0),
    _rb('prune_plan', False, 'Start following closest point of global plan, not first point (if different).'),
    _rd('xy_goal_tolerance', 0.1, 'Within what maximum distance we consider the robot to be in goal'),
    _rd('yaw_goal_tolerance', 0.1, 'Within what maximum angle difference we consider the robot to face goal '
       'direction'),
    _rd('trans_stopped_vel', 0.1, 'Below what maximum velocity we consider the robot to be stopped in translation'),
    _rd('theta_stopped_vel', 0.1, 'Below what maximum rotation velocity we consider the robot to be stopped in '
       'rotation'),
    _rd('sim_time', 1.7, 'The amount of time to roll trajectories out for in seconds', 0),
    _rd('sim_granularity', 0.025, 'The granularity with which to check for collisions along each trajectory in '
       'meters', 0),
    _rd('angular_sim_granularity', 0.1, 'The granularity with which to check for collisions for rotations in '
       'radians', 0),
    _rd('path_distance_bias', 32.0, 'The weight for the path distance part of the cost function', 0.0),
    _rd('goal_distance_bias', 24.0, 'The weight for the goal distance part of the cost function', 0.0),
    _rd('occdist_scale', 0.01, 'The weight for the obstacle distance part of the cost function', 0.0),
    _rd('twirling_scale', 0.0, 'The weight for penalizing any changes in robot heading', 0.0),
    _rd('stop_time_buffer', 0.2, 'The amount of time that the robot must stop before a collision in order for a '
       'trajectory to be considered valid in seconds', 0),
    _rd('oscillation_reset_dist', 0.05, 'The distance the robot must travel before oscillation flags are reset, in '
       'meters', 0),
    _rd('oscillation_reset_angle', 0.2, 'The angle the robot must turn before oscillation flags are reset, in '
       'radians', 0),
    _rd('forward_point_distance', 0.325, 'The distance from the center point of the robot to place an additional '
       'scoring point, in meters'),
    _rd('scaling_speed', 0.25, 'The absolute value of the velocity at which to start scaling the robot\'s '
       'footprint, in m/s', 0),
    _rd('max_scaling_factor', 0.2, 'The maximum factor to scale the robot\'s footprint by', 0),
    _ri('vx_samples', 3, 'The number of samples to use when exploring the x velocity space', 1),
    _ri('vy_samples', 10, 'The number of samples to use when exploring the y velocity space', 1),
    _ri('vth_samples', 20, 'The number of samples to use when exploring the theta velocity space', 1),
    _rb('use_dwa', True, 'Use dynamic window approach to constrain sampling velocities to small window.'),
    _rb('restore_defaults', False, 'Restore to the original configuration.'),
]

#: .cfg file stem -> (group, generated node name used by gen.generate)
RECONFIGURABLE: Dict[str, Tuple[List[Param], str]] = {
    'MoveBase': (MOVE_BASE_CFG, 'move_base'),
    'Costmap2D': (COSTMAP_CFG, 'costmap_2d'),
    'GenericPlugin': (GENERIC_PLUGIN_CFG, 'costmap_2d'),
    'ObstaclePlugin': (OBSTACLE_PLUGIN_CFG, 'costmap_2d'),
    'InflationPlugin': (INFLATION_PLUGIN_CFG, 'costmap_2d'),
    'DWAPlanner': (DWA_CFG, 'dwa_local_planner'),
}

# ---------------------------------------------------------------------------------------------
# parameters read directly (not reconfigurable), for the README and validation

MOVE_BASE_DIRECT: List[Param] = [
    _s('global_costmap/robot_base_frame', 'Robot frame used for goals and plans.'),
    _s('global_costmap/global_frame', 'Frame of goals and global plans.'),
    _d('local_costmap/inscribed_radius', 'Read as move_base does (move_base derives clearing_radius from it) [m].', 0),
    _d('local_costmap/circumscribed_radius', 'Read as move_base does; aggressive_reset clears beyond 4x this '
       '[m].', 0),
    _d('clearing_radius', 'Half side of the window cleared around the robot before a make_plan request [m] '
       '(move_base: circumscribed_radius).', 0),
]

COSTMAP_DIRECT: List[Param] = [
    _s('global_frame', 'Frame of the costmap.'),
    _s('robot_base_frame', 'Frame of the robot base.'),
    _b('rolling_window', 'The costmap is a window that follows the robot.'),
    _b('track_unknown_space', 'Read as costmap_2d does (its layers\' default there); each layer here sets its own.'),
    _b('always_send_full_costmap', 'Publish the whole costmap on every publish cycle (else costmap_updates).'),
]

STATIC_DIRECT: List[Param] = [
    _s('map_topic', 'Topic of the static map (nav_msgs/OccupancyGrid).'),
    _b('first_map_only', 'Use only the first map received.'),
    _b('subscribe_to_updates', 'Accepted; map updates (map_updates topic) are not subscribed.'),
    _b('track_unknown_space', 'Unknown map cells are NO_INFORMATION (else free).'),
    _b('use_maximum', 'Accepted; the static layer is always the base of the master grid.'),
    _i('lethal_cost_threshold', 'Map values at or above this are lethal.', 0, 255),
    _i('unknown_cost_value', 'Map value meaning unknown.', -1, 255),
    _b('trinary_costmap', 'Map values are only free, lethal or unknown.'),
]

OBSTACLE_DIRECT: List[Param] = [
    _b('track_unknown_space', 'Cells never observed are NO_INFORMATION.'),
    _d('transform_tolerance', 'Accepted; scans are transformed at their own stamps [s].', 0),
    _s('observation_sources', 'Space-separated list of sources (each a sub-namespace).'),
]

SOURCE_DIRECT: List[Param] = [
    _d('observation_persistence', 'Accepted; each update uses the messages received since the last one [s].', 0),
    _d('expected_update_rate', 'Maximum age of the newest message before the sensor is out of date [s] '
       '(0: never).', 0),
    _s('data_type', 'LaserScan or PointCloud2.'),
    _d('min_obstacle_height', 'Lower end of the height band in the costmap frame [m]: cloud points outside it are '
       'dropped; a LaserScan marks only when its sensor is inside it.'),
    _d('max_obstacle_height', 'Upper end of the height band [m] (capped by the layer\'s max_obstacle_height).'),
    _b('inf_is_valid', 'LaserScan: out-of-range readings clear along their whole beam (read, unused, for a cloud).'),
    _b('clearing', 'The source clears free space by raytracing.'),
    _b('marking', 'The source marks obstacles.'),
    _s('topic', 'Topic of the sensor_msgs/LaserScan or sensor_msgs/PointCloud2.'),
    _s('sensor_frame', 'Frame of the sensor origin (\'\': the message\'s header frame).'),
]
#: the message types an observation source can have (``data_type``)
SOURCE_DATA_TYPES = ('LaserScan', 'PointCloud2')
SOURCE_SEARCHED: List[Param] = [
    _d('obstacle_range', 'Maximum range at which hits are marked [m] (searched upwards).', 0),
    _d('raytrace_range', 'Maximum range cleared by raytracing [m] (searched upwards).', 0),
]

NAVFN_DIRECT: List[Param] = [
    _b('visualize_potential', 'Accepted; no potential field is published.'),
    _b('allow_unknown', 'Plan through unknown space and accept goals in it.'),
    _d('planner_window_x', 'Accepted; the whole costmap is searched [m].'),
    _d('planner_window_y', 'Accepted; the whole costmap is searched [m].'),
    _d('default_tolerance', 'Accept the reachable cell nearest to an unreachable goal within this [m].', 0),
]

DWA_DIRECT: List[Param] = [
    _b('sum_scores', 'Obstacle cost of a trajectory is the sum of its cell costs (else the maximum).'),
    _b('publish_cost_grid_pc', 'Accepted; no cost grid cloud is published.'),
    _s('global_frame_id', 'Frame of the trajectory cloud.'),
    _b('publish_traj_pc', 'Publish the scored trajectories as trajectory_cloud (sensor_msgs/PointCloud2).'),
    _d('cheat_factor', 'Scale of the distance to the goal below which the nose is no longer kept on the path.',
       0),
    _b('latch_xy_goal_tolerance', 'Once within xy_goal_tolerance, only rotate even if the robot drifts out.'),
]
#: DWAPlannerROS warns when the pre-Noetic name is set (``warnRenamedParameter``): new -> old
DWA_RENAMED: List[Tuple[str, str]] = [
    ('max_vel_trans', 'max_trans_vel'), ('min_vel_trans', 'min_trans_vel'), ('max_vel_theta', 'max_rot_vel'),
    ('min_vel_theta', 'min_rot_vel'), ('acc_lim_trans', 'acc_limit_trans'), ('theta_stopped_vel', 'rot_stopped_vel'),
]

CLEAR_RECOVERY_DIRECT: List[Param] = [
    _d('reset_distance', 'Side of the square around the robot outside which layers are reset [m].', 0),
    _b('invert_area_to_clear', 'Reset inside the square instead.'),
    _b('force_updating', 'Accepted; the costmaps are recomputed right after clearing anyway.'),
    _s('affected_maps', 'global, local or both.'),
]
ROTATE_RECOVERY_DIRECT: List[Param] = [
    _d('sim_granularity', 'Angular step of the collision check [rad].', 0),
    _d('frequency', 'Accepted; the rotation is commanded at the controller frequency [Hz].', 0),
]
#: RotateRecovery reads these from ~TrajectoryPlannerROS with loadParameterWithDeprecation: (current, old name)
ROTATE_BLP: List[Tuple[Param, str]] = [
    (_d('acc_lim_theta', 'Angular acceleration limit of the in-place rotation [rad/s^2].', 0), 'acc_lim_th'),
    (_d('max_vel_theta', 'Maximum rotational velocity of the in-place rotation [rad/s].', 0), 'max_rotational_vel'),
    (_d('min_in_place_vel_theta', 'Minimum rotational velocity of the in-place rotation [rad/s].', 0),
     'min_in_place_rotational_vel'),
]
ROTATE_BLP_TOLERANCE = _d('yaw_goal_tolerance', 'The rotation ends within this of a full turn [rad].', 0)
#: DWAPlannerROS checks a controller_frequency found searching upwards from its namespace
CONTROLLER_FREQUENCY = _d('controller_frequency', 'Rate of the control loop [Hz].', 0)

_ROBOT_RADIUS = next(p for p in COSTMAP_CFG if p.name == 'robot_radius')

PLUGIN_TYPES = {
    'costmap_2d::StaticLayer': 'static',
    'costmap_2d::ObstacleLayer': 'obstacle',
    'costmap_2d::VoxelLayer': 'obstacle',     # treated as a 2-D obstacle layer
    'costmap_2d::InflationLayer': 'inflation',
}
ClearTypes = ('clear_costmap_recovery/ClearCostmapRecovery',)
RotateTypes = ('rotate_recovery/RotateRecovery',)
GLOBAL_PLANNERS = ('navfn/NavfnROS',)                      # the MCP planner stands in for navfn
LOCAL_PLANNERS = ('dwa_local_planner/DWAPlannerROS',)       # the vectorised DWA controller
