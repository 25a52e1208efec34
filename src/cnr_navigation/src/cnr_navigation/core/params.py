"""move_base's parameter tree: declarations, defaults, and reading it one parameter at a time (ROS-free).

This is the one place that knows the parameters. It serves three uses:

* the dynamic_reconfigure ``.cfg`` scripts in ``cfg/`` build their ParameterGenerators from the
  reconfigurable groups below (:data:`RECONFIGURABLE`), so names, defaults and ranges agree;
* :func:`read_navigation_params` reads the whole tree through a :class:`ParamReader`, one
  ``getParam`` / ``hasParam`` / ``searchParam`` / ``setParam`` per value, in the order and with
  the code defaults of move_base, costmap_2d, navfn, dwa_local_planner and the recoveries
  (navigation@noetic-devel). A move_base start-up costs the master one XML-RPC call per value, and
  a later experiment measures that start-up, so it is reproduced rather than replaced by one
  ``getParam('~')``;
* the README's parameter tables list the same declarations.

Defaults here are move_base's *code* defaults; the TurtleBot values are in
``config/navigation/*.yaml``. Every value is validated; a bad one raises
:class:`cnr_params.ConfigError` naming the parameter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Protocol, Sequence, Tuple

from cnr_params import ConfigError

from cnr_navigation.core.costmap import CostmapConfig, InflationLayerConfig, ObstacleLayerConfig, StaticLayerConfig
from cnr_navigation.core.dwa import DWAConfig
from cnr_navigation.core.move_base import MoveBaseConfig, RecoverySpec, default_recovery_specs
from cnr_navigation.core.planner import PlannerConfig
from cnr_navigation.core.recovery import ClearCostmapConfig, RotateConfig


@dataclass(frozen=True)
class Param:
    """One declared parameter.

    Attributes:
        name: name relative to its namespace.
        kind: 'double', 'int', 'bool' or 'str'.
        default: code default.
        description: one line, with the unit.
        minimum / maximum: range for dynamic_reconfigure and validation (None: unbounded).
    """

    name: str
    kind: str
    default: Any
    description: str
    minimum: Optional[float] = None
    maximum: Optional[float] = None


def _d(name: str, default: float, description: str, minimum: Optional[float] = None,
       maximum: Optional[float] = None) -> Param:
    return Param(name, 'double', default, description, minimum, maximum)


def _i(name: str, default: int, description: str, minimum: Optional[float] = None,
       maximum: Optional[float] = None) -> Param:
    return Param(name, 'int', default, description, minimum, maximum)


def _b(name: str, default: bool, description: str) -> Param:
    return Param(name, 'bool', default, description)


def _s(name: str, default: str, description: str) -> Param:
    return Param(name, 'str', default, description)


# ---------------------------------------------------------------------------------------------
# reconfigurable groups (one dynamic_reconfigure server each), as the .cfg files of noetic

MOVE_BASE_CFG: List[Param] = [
    _s('base_global_planner', 'navfn/NavfnROS', 'The name of the plugin for the global planner to use with move_base.'),
    _s('base_local_planner', 'base_local_planner/TrajectoryPlannerROS',
       'The name of the plugin for the local planner to use with move_base.'),
    _d('planner_frequency', 0.0, 'The rate in Hz at which to run the planning loop.', 0, 100),
    _d('controller_frequency', 20.0, 'The rate in Hz at which to run the control loop and send velocity commands '
       'to the base.', 0, 100),
    _d('planner_patience', 5.0, 'How long the planner will wait in seconds in an attempt to find a valid plan '
       'before space-clearing operations are performed.', 0, 100),
    _d('controller_patience', 15.0, 'How long the controller will wait in seconds without receiving a valid '
       'control before space-clearing operations are performed.', 0, 100),
    _i('max_planning_retries', -1, 'How many times we will recall the planner in an attempt to find a valid plan '
       'before space-clearing operations are performed', -1, 1000),
    _d('conservative_reset_dist', 3.0, 'The distance away from the robot in meters at which obstacles will be '
       'cleared from the costmap when attempting to clear space in the map.', 0, 50),
    _b('recovery_behavior_enabled', True, 'Whether or not to enable the move_base recovery behaviors to attempt '
       'to clear out space.'),
    _b('clearing_rotation_allowed', True, 'Determines whether or not the robot will attempt an in-place rotation '
       'when attempting to clear out space.'),
    _b('shutdown_costmaps', False, 'Determines whether or not to shutdown the costmaps of the node when move_base '
       'is in an inactive state'),
    _d('oscillation_timeout', 0.0, 'How long in seconds to allow for oscillation before executing recovery '
       'behaviors.', 0, 60),
    _d('oscillation_distance', 0.5, 'How far in meters the robot must move to be considered not to be '
       'oscillating.', 0, 10),
    _b('make_plan_clear_costmap', True, 'Whether or not to clear the global costmap on make_plan service call.'),
    _b('make_plan_add_unreachable_goal', True, 'Whether or not to add the original goal to the path if it is '
       'unreachable in the make_plan service call.'),
    _b('restore_defaults', False, 'Restore to the original configuration'),
]

COSTMAP_CFG: List[Param] = [
    _d('transform_tolerance', 0.3, 'Specifies the delay in transform (tf) data that is tolerable in seconds.', 0, 10),
    _d('update_frequency', 5.0, 'The frequency in Hz for the map to be updated.', 0, 100),
    _d('publish_frequency', 0.0, 'The frequency in Hz for the map to be publish display information.', 0, 100),
    # costmap_2d declares width/height as int_t [m]; doubles here so a 4.0 m window loads as it does in C++
    _d('width', 10.0, 'The width of the map in meters.', 0, None),
    _d('height', 10.0, 'The height of the map in meters.', 0, None),
    _d('resolution', 0.05, 'The resolution of the map in meters/cell.', 0, 50),
    _d('origin_x', 0.0, 'The x origin of the map in the global frame in meters.'),
    _d('origin_y', 0.0, 'The y origin of the map in the global frame in meters.'),
    _s('footprint', '[]', 'The footprint of the robot specified in the robot_base_frame coordinate frame as a list '
       'in the format: [ [x1, y1], [x2, y2], ...., [xn, yn] ].'),
    _d('robot_radius', 0.46, 'The radius of the robot in meters, this parameter should only be set for circular '
       'robots, all others should use the footprint parameter described above.', 0, 10),
    _d('footprint_padding', 0.01, 'How much to pad (increase the size of) the footprint, in meters.'),
]

GENERIC_PLUGIN_CFG: List[Param] = [
    _b('enabled', True, 'Whether to apply this plugin or not'),
]

OBSTACLE_PLUGIN_CFG: List[Param] = [
    _b('enabled', True, 'Whether to apply this plugin or not'),
    _b('footprint_clearing_enabled', True, 'Whether to clear the robot\'s footprint of lethal obstacles'),
    _d('max_obstacle_height', 2.0, 'The maximum height of any obstacle to be inserted into the costmap in meters.',
       0, 50),
    _i('combination_method', 1, 'Method for combining two layers (0 overwrite, 1 maximum)', 0, 2),
]

INFLATION_PLUGIN_CFG: List[Param] = [
    _b('enabled', True, 'Whether to apply this plugin or not'),
    _d('cost_scaling_factor', 10.0, 'A scaling factor to apply to cost values during inflation.', 0, 100),
    _d('inflation_radius', 0.55, 'The radius in meters to which the map inflates obstacle cost values.', 0, 50),
    _b('inflate_unknown', False, 'Whether to inflate unknown cells.'),
]

DWA_CFG: List[Param] = [
    _d('max_vel_trans', 0.55, 'The absolute value of the maximum translational velocity for the robot in m/s', 0),
    _d('min_vel_trans', 0.1, 'The absolute value of the minimum translational velocity for the robot in m/s', 0),
    _d('max_vel_x', 0.55, 'The maximum x velocity for the robot in m/s'),
    _d('min_vel_x', 0.0, 'The minimum x velocity for the robot in m/s'),
    _d('max_vel_y', 0.1, 'The maximum y velocity for the robot in m/s'),
    _d('min_vel_y', -0.1, 'The minimum y velocity for the robot in m/s'),
    _d('max_vel_theta', 1.0, 'The absolute value of the maximum rotational velocity for the robot in rad/s', 0),
    _d('min_vel_theta', 0.4, 'The absolute value of the minimum rotational velocity for the robot in rad/s', 0),
    _d('acc_lim_x', 2.5, 'The acceleration limit of the robot in the x direction', 0, 20),
    _d('acc_lim_y', 2.5, 'The acceleration limit of the robot in the y direction', 0, 20),
    _d('acc_lim_theta', 3.2, 'The acceleration limit of the robot in the theta direction', 0, 20),
    _d('acc_lim_trans', 0.1, 'The absolute value of the maximum translational acceleration for the robot in m/s^2', 0),
    _b('prune_plan', False, 'Start following closest point of global plan, not first point (if different).'),
    _d('xy_goal_tolerance', 0.1, 'Within what maximum distance we consider the robot to be in goal'),
    _d('yaw_goal_tolerance', 0.1, 'Within what maximum angle difference we consider the robot to face goal '
       'direction'),
    _d('trans_stopped_vel', 0.1, 'Below what maximum velocity we consider the robot to be stopped in translation'),
    _d('theta_stopped_vel', 0.1, 'Below what maximum rotation velocity we consider the robot to be stopped in '
       'rotation'),
    _d('sim_time', 1.7, 'The amount of time to roll trajectories out for in seconds', 0),
    _d('sim_granularity', 0.025, 'The granularity with which to check for collisions along each trajectory in '
       'meters', 0),
    _d('angular_sim_granularity', 0.1, 'The granularity with which to check for collisions for rotations in '
       'radians', 0),
    _d('path_distance_bias', 32.0, 'The weight for the path distance part of the cost function', 0.0),
    _d('goal_distance_bias', 24.0, 'The weight for the goal distance part of the cost function', 0.0),
    _d('occdist_scale', 0.01, 'The weight for the obstacle distance part of the cost function', 0.0),
    _d('twirling_scale', 0.0, 'The weight for penalizing any changes in robot heading', 0.0),
    _d('stop_time_buffer', 0.2, 'The amount of time that the robot must stop before a collision in order for a '
       'trajectory to be considered valid in seconds', 0),
    _d('oscillation_reset_dist', 0.05, 'The distance the robot must travel before oscillation flags are reset, in '
       'meters', 0),
    _d('oscillation_reset_angle', 0.2, 'The angle the robot must turn before oscillation flags are reset, in '
       'radians', 0),
    _d('forward_point_distance', 0.325, 'The distance from the center point of the robot to place an additional '
       'scoring point, in meters'),
    _d('scaling_speed', 0.25, 'The absolute value of the velocity at which to start scaling the robot\'s '
       'footprint, in m/s', 0),
    _d('max_scaling_factor', 0.2, 'The maximum factor to scale the robot\'s footprint by', 0),
    _i('vx_samples', 3, 'The number of samples to use when exploring the x velocity space', 1),
    _i('vy_samples', 10, 'The number of samples to use when exploring the y velocity space', 1),
    _i('vth_samples', 20, 'The number of samples to use when exploring the theta velocity space', 1),
    _b('use_dwa', True, 'Use dynamic window approach to constrain sampling velocities to small window.'),
    _b('restore_defaults', False, 'Restore to the original configuration.'),
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
    _s('global_costmap/robot_base_frame', 'base_link', 'Robot frame used for goals and plans.'),
    _s('global_costmap/global_frame', 'map', 'Frame of goals and global plans.'),
    _d('local_costmap/inscribed_radius', 0.325, 'Read as move_base does; sets the default clearing_radius [m].', 0),
    _d('local_costmap/circumscribed_radius', 0.46, 'Read as move_base does; aggressive_reset clears beyond 4x this '
       '[m].', 0),
    _d('clearing_radius', 0.46, 'Half side of the window cleared around the robot before a make_plan request [m] '
       '(default: circumscribed_radius).', 0),
]

COSTMAP_DIRECT: List[Param] = [
    _s('global_frame', 'map', 'Frame of the costmap.'),
    _s('robot_base_frame', 'base_link', 'Frame of the robot base.'),
    _b('rolling_window', False, 'The costmap is a window that follows the robot.'),
    _b('track_unknown_space', False, 'Default for the layers\' track_unknown_space.'),
    _b('always_send_full_costmap', False, 'Publish the whole costmap on every publish cycle (else costmap_updates).'),
]

STATIC_DIRECT: List[Param] = [
    _s('map_topic', 'map', 'Topic of the static map (nav_msgs/OccupancyGrid).'),
    _b('first_map_only', False, 'Use only the first map received.'),
    _b('subscribe_to_updates', False, 'Accepted; map updates (map_updates topic) are not subscribed.'),
    _b('track_unknown_space', True, 'Unknown map cells are NO_INFORMATION (else free).'),
    _b('use_maximum', False, 'Accepted; the static layer is always the base of the master grid.'),
    _i('lethal_cost_threshold', 100, 'Map values at or above this are lethal.', 0, 255),
    _i('unknown_cost_value', -1, 'Map value meaning unknown.', -1, 255),
    _b('trinary_costmap', True, 'Map values are only free, lethal or unknown.'),
]

OBSTACLE_DIRECT: List[Param] = [
    _b('track_unknown_space', False, 'Cells never observed are NO_INFORMATION (default: the costmap\'s).'),
    _d('transform_tolerance', 0.2, 'Accepted; scans are transformed at their own stamps [s].', 0),
    _s('observation_sources', '', 'Space-separated list of sources (each a sub-namespace).'),
]

SOURCE_DIRECT: List[Param] = [
    _d('observation_persistence', 0.0, 'Accepted; each update uses the scans received since the last one [s].', 0),
    _d('expected_update_rate', 0.0, 'Maximum age of the newest scan before the sensor is out of date [s] '
       '(0: never).', 0),
    _s('data_type', 'PointCloud', 'Must be LaserScan.'),
    _d('min_obstacle_height', 0.0, 'Scans from sensors below this height do not mark [m].'),
    _d('max_obstacle_height', 2.0, 'Scans from sensors above this height do not mark [m].'),
    _b('inf_is_valid', False, 'Out-of-range readings clear along their whole beam.'),
    _b('clearing', False, 'The source clears free space by raytracing.'),
    _b('marking', True, 'The source marks obstacles.'),
    _s('topic', '', 'Topic of the sensor_msgs/LaserScan (default: the source name).'),
    _s('sensor_frame', '', 'Frame of the sensor (default: the scan\'s header frame).'),
]
SOURCE_SEARCHED: List[Param] = [
    _d('obstacle_range', 2.5, 'Maximum range at which hits are marked [m] (searched upwards).', 0),
    _d('raytrace_range', 3.0, 'Maximum range cleared by raytracing [m] (searched upwards).', 0),
]

NAVFN_DIRECT: List[Param] = [
    _b('visualize_potential', False, 'Accepted; no potential field is published.'),
    _b('allow_unknown', True, 'Plan through unknown space and accept goals in it.'),
    _d('planner_window_x', 0.0, 'Accepted; the whole costmap is searched [m].'),
    _d('planner_window_y', 0.0, 'Accepted; the whole costmap is searched [m].'),
    _d('default_tolerance', 0.0, 'Accept the reachable cell nearest to an unreachable goal within this [m].', 0),
]

DWA_DIRECT: List[Param] = [
    _b('sum_scores', False, 'Obstacle cost of a trajectory is the sum of its cell costs (else the maximum).'),
    _b('publish_cost_grid_pc', False, 'Accepted; no cost grid cloud is published.'),
    _s('global_frame_id', 'odom', 'Frame of the trajectory cloud.'),
    _b('publish_traj_pc', False, 'Publish the scored trajectories as trajectory_cloud (sensor_msgs/PointCloud2).'),
    _d('cheat_factor', 1.0, 'Scale of the distance to the goal below which the nose is no longer kept on the path.',
       0),
    _b('latch_xy_goal_tolerance', False, 'Once within xy_goal_tolerance, only rotate even if the robot drifts out.'),
]
#: DWAPlannerROS warns when the pre-Noetic name is set (``warnRenamedParameter``): new -> old
DWA_RENAMED: List[Tuple[str, str]] = [
    ('max_vel_trans', 'max_trans_vel'), ('min_vel_trans', 'min_trans_vel'), ('max_vel_theta', 'max_rot_vel'),
    ('min_vel_theta', 'min_rot_vel'), ('acc_lim_trans', 'acc_limit_trans'), ('theta_stopped_vel', 'rot_stopped_vel'),
]

CLEAR_RECOVERY_DIRECT: List[Param] = [
    _d('reset_distance', 3.0, 'Side of the square around the robot outside which layers are reset [m].', 0),
    _b('invert_area_to_clear', False, 'Reset inside the square instead.'),
    _b('force_updating', False, 'Accepted; the costmaps are recomputed right after clearing anyway.'),
    _s('affected_maps', 'both', 'global, local or both.'),
]
ROTATE_RECOVERY_DIRECT: List[Param] = [
    _d('sim_granularity', 0.017, 'Angular step of the collision check [rad].', 0),
    _d('frequency', 20.0, 'Accepted; the rotation is commanded at the controller frequency [Hz].', 0),
]
#: RotateRecovery reads these from ~TrajectoryPlannerROS with loadParameterWithDeprecation: (current, old, default)
ROTATE_BLP: List[Tuple[str, str, float]] = [
    ('acc_lim_theta', 'acc_lim_th', 3.2), ('max_vel_theta', 'max_rotational_vel', 1.0),
    ('min_in_place_vel_theta', 'min_in_place_rotational_vel', 0.4),
]

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


# ---------------------------------------------------------------------------------------------
# reading

class ParamReader(Protocol):
    """One master call per method call (rospy in the node, a dict in tests). Names are absolute."""

    def get(self, name: str, default: Any) -> Any:
        """getParam; ``default`` when the parameter is not set."""

    def has(self, name: str) -> bool:
        """hasParam."""

    def search(self, namespace: str, key: str) -> Optional[str]:
        """searchParam for ``key`` upwards from ``namespace``; the full name found or None."""

    def set(self, name: str, value: Any) -> None:
        """setParam."""


def check_value(p: Param, value: Any, source: str) -> Any:
    """``value`` converted to ``p.kind`` and range-checked; ConfigError naming ``source``/``p.name``."""
    def bad(problem: str) -> ConfigError:
        return ConfigError(source, p.name, problem)
    if p.kind == 'bool':
        if not isinstance(value, bool):
            raise bad(f'expected true or false, got {value!r}')
        return value
    if p.kind == 'str':
        if not isinstance(value, str):
            raise bad(f'expected a string, got {value!r}')
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise bad(f'expected a number, got {value!r}')
    if p.kind == 'int':
        if isinstance(value, float):
            if not value.is_integer():
                raise bad(f'expected an integer, got {value!r}')
            value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise bad(f'must be finite, got {value}')
    if p.minimum is not None and value < p.minimum:
        raise bad(f'must be >= {p.minimum:g}, got {value}')
    if p.maximum is not None and value > p.maximum:
        raise bad(f'must be <= {p.maximum:g}, got {value}')
    return value


def _join(ns: str, name: str) -> str:
    return f'{ns.rstrip("/")}/{name}'


def read_group(reader: ParamReader, ns: str, params: Sequence[Param],
               defaults: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """Read each parameter of ``params`` under ``ns`` with one getParam, validated."""
    out: Dict[str, Any] = {}
    for p in params:
        default = (defaults or {}).get(p.name, p.default)
        out[p.name] = check_value(p, reader.get(_join(ns, p.name), default), ns)
    return out


@dataclass
class SourceParams:
    """One observation source of an obstacle layer."""

    name: str
    topic: str
    sensor_frame: str
    expected_update_rate: float
    layer: ObstacleLayerConfig


@dataclass
class CostmapParams:
    """A costmap's configuration plus what the node needs around it."""

    name: str
    config: CostmapConfig
    always_send_full_costmap: bool
    map_topic: str
    first_map_only: bool
    plugins: List[Tuple[str, str]]            # (name, kind) in order
    sources: List[SourceParams]
    footprint: List[Tuple[float, float]]


@dataclass
class RecoveryParams:
    name: str
    type: str
    clear: Optional[ClearCostmapConfig] = None
    rotate: Optional[RotateConfig] = None


@dataclass
class NavigationParams:
    """Everything move_base reads at start-up."""

    move_base: MoveBaseConfig
    base_global_planner: str
    base_local_planner: str
    robot_base_frame: str
    global_frame: str
    clearing_radius: float
    circumscribed_radius: float
    global_costmap: CostmapParams
    local_costmap: CostmapParams
    planner: PlannerConfig
    dwa: DWAConfig
    dwa_extra: Dict[str, Any]
    odom_topic: str
    recoveries: List[RecoveryParams]
    warnings: List[str] = field(default_factory=list)


def parse_footprint(text: Any, source: str) -> List[Tuple[float, float]]:
    import yaml
    value = text
    if isinstance(text, str):
        try:
            value = yaml.safe_load(text) if text.strip() else []
        except yaml.YAMLError:
            raise ConfigError(source, 'footprint', f'cannot parse {text!r}') from None
    if value is None:
        value = []
    if not isinstance(value, list) or not all(isinstance(v, (list, tuple)) and len(v) == 2 for v in value):
        raise ConfigError(source, 'footprint', f'expected [[x1, y1], [x2, y2], ...], got {text!r}')
    pts = []
    for v in value:
        if not all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v):
            raise ConfigError(source, 'footprint', f'expected finite numbers, got {v!r}')
        pts.append((float(v[0]), float(v[1])))
    if pts and len(pts) < 3:
        raise ConfigError(source, 'footprint', 'needs at least 3 points')
    return pts


def read_costmap(reader: ParamReader, node_ns: str, name: str, warnings: List[str]) -> CostmapParams:
    """Costmap2DROS's reads for ``~<name>`` and those of its plugins (static, obstacle, inflation)."""
    ns = _join(node_ns, name)
    direct = read_group(reader, ns, COSTMAP_DIRECT)
    has_plugins = reader.has(_join(ns, 'plugins'))
    for old in ('static_map', 'map_type'):          # warnForOldParameters
        if reader.has(_join(ns, old)):
            warnings.append(f'{ns}: parameter {old} is ignored because plugins are used (as costmap_2d)')
    plugins: List[Tuple[str, str]] = []
    if has_plugins:
        raw = reader.get(_join(ns, 'plugins'), [])
        if not isinstance(raw, list):
            raise ConfigError(ns, 'plugins', f'expected a list of {{name, type}}, got {raw!r}')
        for i, entry in enumerate(raw):
            if not isinstance(entry, dict) or not isinstance(entry.get('name'), str) or \
                    not isinstance(entry.get('type'), str):
                raise ConfigError(ns, f'plugins[{i}]', f'expected {{name: ..., type: ...}}, got {entry!r}')
            kind = PLUGIN_TYPES.get(entry['type'])
            if kind is None:
                raise ConfigError(ns, f'plugins[{i}].type',
                                  f"unknown plugin type '{entry['type']}' (expected one of: {', '.join(PLUGIN_TYPES)})")
            plugins.append((entry['name'], kind))
    else:   # costmap_2d's loadOldParameters: static map or not, then obstacles and inflation
        plugins = [('static_layer', 'static'), ('obstacle_layer', 'obstacle'), ('inflation_layer', 'inflation')]
    kinds = [k for _, k in plugins]
    for k in set(kinds):
        if kinds.count(k) > 1:
            raise ConfigError(ns, 'plugins', f'more than one {k} layer is not supported')

    static_cfg: Optional[StaticLayerConfig] = None
    obstacle_cfg: Optional[ObstacleLayerConfig] = None
    inflation_cfg: Optional[InflationLayerConfig] = None
    map_topic, first_map_only = 'map', False
    sources: List[SourceParams] = []
    for pname, kind in plugins:
        pns = _join(ns, pname)
        if kind == 'static':
            s = read_group(reader, pns, STATIC_DIRECT, {'track_unknown_space': True})
            g = read_group(reader, pns, GENERIC_PLUGIN_CFG)
            map_topic, first_map_only = s['map_topic'], s['first_map_only']
            static_cfg = StaticLayerConfig(enabled=g['enabled'], track_unknown_space=s['track_unknown_space'],
                                           lethal_cost_threshold=s['lethal_cost_threshold'],
                                           unknown_cost_value=s['unknown_cost_value'],
                                           trinary_costmap=s['trinary_costmap'], use_maximum=s['use_maximum'])
        elif kind == 'obstacle':
            o = read_group(reader, pns, OBSTACLE_DIRECT, {'track_unknown_space': direct['track_unknown_space']})
            names = o['observation_sources'].split()
            for src in names:
                sns = _join(pns, src)
                sp = read_group(reader, sns, SOURCE_DIRECT, {'topic': src})
                if sp['data_type'] != 'LaserScan':
                    raise ConfigError(sns, 'data_type', f"unsupported '{sp['data_type']}' (only LaserScan)")
                ranges = {}
                for p in SOURCE_SEARCHED:
                    found = reader.search(sns, p.name)
                    ranges[p.name] = check_value(p, reader.get(found, p.default), sns) if found else p.default
                sources.append(SourceParams(src, sp['topic'], sp['sensor_frame'], sp['expected_update_rate'],
                                            ObstacleLayerConfig(
                                                track_unknown_space=o['track_unknown_space'],
                                                obstacle_range=ranges['obstacle_range'],
                                                raytrace_range=ranges['raytrace_range'],
                                                min_obstacle_height=sp['min_obstacle_height'],
                                                max_obstacle_height=sp['max_obstacle_height'],
                                                inf_is_valid=sp['inf_is_valid'], marking=sp['marking'],
                                                clearing=sp['clearing'])))
            r = read_group(reader, pns, OBSTACLE_PLUGIN_CFG)
            base = sources[0].layer if sources else ObstacleLayerConfig(track_unknown_space=o['track_unknown_space'])
            obstacle_cfg = ObstacleLayerConfig(
                enabled=r['enabled'], footprint_clearing_enabled=r['footprint_clearing_enabled'],
                combination_method=r['combination_method'], track_unknown_space=base.track_unknown_space,
                obstacle_range=base.obstacle_range, raytrace_range=base.raytrace_range,
                min_obstacle_height=base.min_obstacle_height,
                max_obstacle_height=min(base.max_obstacle_height, r['max_obstacle_height']),
                inf_is_valid=base.inf_is_valid, marking=base.marking, clearing=base.clearing)
        else:
            r = read_group(reader, pns, INFLATION_PLUGIN_CFG)
            inflation_cfg = InflationLayerConfig(enabled=r['enabled'], inflation_radius=r['inflation_radius'],
                                                 cost_scaling_factor=r['cost_scaling_factor'],
                                                 inflate_unknown=r['inflate_unknown'])
    # makeFootprintFromParams: footprint, else robot_radius, each searched upwards
    footprint: List[Tuple[float, float]] = []
    radius = 0.46
    found = reader.search(ns, 'footprint')
    if found:
        footprint = parse_footprint(reader.get(found, '[]'), ns)
    if not footprint:
        found = reader.search(ns, 'robot_radius')
        if found:
            radius = check_value(_ROBOT_RADIUS, reader.get(found, radius), ns)
    else:
        radius = max(math.hypot(x, y) for x, y in footprint)
        warnings.append(f'{ns}: polygon footprint approximated by its circumscribed circle (r = {radius:.3f} m)')
    r = read_group(reader, ns, COSTMAP_CFG, {'robot_radius': radius})
    cfg = CostmapConfig(global_frame=direct['global_frame'], robot_base_frame=direct['robot_base_frame'],
                        rolling_window=direct['rolling_window'], width=r['width'], height=r['height'],
                        resolution=r['resolution'], origin_x=r['origin_x'], origin_y=r['origin_y'],
                        robot_radius=radius, footprint_padding=r['footprint_padding'],
                        update_frequency=r['update_frequency'], publish_frequency=r['publish_frequency'],
                        transform_tolerance=r['transform_tolerance'], static_layer=static_cfg,
                        obstacle_layer=obstacle_cfg, inflation_layer=inflation_cfg)
    if cfg.resolution <= 0:
        raise ConfigError(ns, 'resolution', f'must be > 0, got {cfg.resolution}')
    return CostmapParams(name, cfg, direct['always_send_full_costmap'], map_topic, first_map_only, plugins, sources,
                         footprint)


def read_recoveries(reader: ParamReader, node_ns: str, cfg: MoveBaseConfig,
                    circumscribed_radius: float) -> List[RecoveryParams]:
    """move_base's ``loadRecoveryBehaviors`` (or the defaults) and each behaviour's initialize()."""
    raw = reader.get(_join(node_ns, 'recovery_behaviors'), None)
    specs: List[RecoverySpec]
    if raw is None:
        specs = default_recovery_specs(cfg.clearing_rotation_allowed)
        reader.set(_join(node_ns, 'conservative_reset/reset_distance'), cfg.conservative_reset_dist)
        reader.set(_join(node_ns, 'aggressive_reset/reset_distance'), circumscribed_radius * 4)
    else:
        if not isinstance(raw, list):
            raise ConfigError(node_ns, 'recovery_behaviors', f'expected a list of {{name, type}}, got {raw!r}')
        specs = []
        for i, entry in enumerate(raw):
            if not isinstance(entry, dict) or not isinstance(entry.get('name'), str) or \
                    entry.get('type') not in (ClearTypes + RotateTypes):
                raise ConfigError(node_ns, f'recovery_behaviors[{i}]',
                                  f'expected {{name: ..., type: one of {", ".join(ClearTypes + RotateTypes)}}}, '
                                  f'got {entry!r}')
            specs.append(RecoverySpec(entry['name'], entry['type']))
    out: List[RecoveryParams] = []
    for spec in specs:
        rns = _join(node_ns, spec.name)
        if spec.type in ClearTypes:
            r = read_group(reader, rns, CLEAR_RECOVERY_DIRECT)
            if r['affected_maps'] not in ('global', 'local', 'both'):
                raise ConfigError(rns, 'affected_maps', f"expected global, local or both, got '{r['affected_maps']}'")
            layers = reader.get(_join(rns, 'layer_names'), ['obstacles'])
            if not isinstance(layers, list) or not all(isinstance(v, str) for v in layers):
                raise ConfigError(rns, 'layer_names', f'expected a list of layer names, got {layers!r}')
            out.append(RecoveryParams(spec.name, spec.type, clear=ClearCostmapConfig(
                reset_distance=r['reset_distance'], affected_maps=r['affected_maps'], layer_names=list(layers),
                invert_area_to_clear=r['invert_area_to_clear'], force_updating=r['force_updating'])))
        else:
            r = read_group(reader, rns, ROTATE_RECOVERY_DIRECT)
            blp = _join(node_ns, 'TrajectoryPlannerROS')
            values = {}
            for current, old, default in ROTATE_BLP:
                p = _d(current, default, '', 0)
                if reader.has(_join(blp, current)):
                    values[current] = check_value(p, reader.get(_join(blp, current), default), blp)
                elif reader.has(_join(blp, old)):
                    values[current] = check_value(p, reader.get(_join(blp, old), default), blp)
                else:
                    values[current] = default
            tol = check_value(_d('yaw_goal_tolerance', 0.10, '', 0),
                              reader.get(_join(blp, 'yaw_goal_tolerance'), 0.10), blp)
            out.append(RecoveryParams(spec.name, spec.type, rotate=RotateConfig(
                sim_granularity=r['sim_granularity'], frequency=r['frequency'], acc_lim_th=values['acc_lim_theta'],
                max_rotational_vel=values['max_vel_theta'],
                min_in_place_rotational_vel=values['min_in_place_vel_theta'], yaw_goal_tolerance=tol)))
    return out


def dwa_config(values: Dict[str, Any], extra: Dict[str, Any]) -> DWAConfig:
    """A :class:`DWAConfig` from the DWAPlanner.cfg group plus the direct reads."""
    names = {f for f in DWAConfig.__dataclass_fields__}
    kwargs = {k: v for k, v in values.items() if k in names}
    kwargs['latch_xy_goal_tolerance'] = extra.get('latch_xy_goal_tolerance', False)
    kwargs['cheat_factor'] = extra.get('cheat_factor', 1.0)
    kwargs['sum_scores'] = extra.get('sum_scores', False)
    return DWAConfig(**kwargs)


def move_base_config(values: Dict[str, Any]) -> MoveBaseConfig:
    names = {f for f in MoveBaseConfig.__dataclass_fields__}
    return MoveBaseConfig(**{k: v for k, v in values.items() if k in names})


def read_navigation_params(reader: ParamReader, node_ns: str) -> NavigationParams:
    """Read move_base's parameter tree under ``node_ns`` (e.g. '/move_base') in move_base's order.

    The dynamic_reconfigure servers read their groups again when they start (as in move_base);
    here each reconfigurable value is read once to validate it before any server exists.

    Raises:
        ConfigError: a value has the wrong type or is out of range, or a plugin/recovery is unknown.
    """
    warnings: List[str] = []
    mb = read_group(reader, node_ns, MOVE_BASE_CFG[:2])                         # planners
    if mb['base_global_planner'] not in GLOBAL_PLANNERS:
        raise ConfigError(node_ns, 'base_global_planner',
                          f"unknown planner '{mb['base_global_planner']}' (implemented: {', '.join(GLOBAL_PLANNERS)})")
    if mb['base_local_planner'] not in LOCAL_PLANNERS:
        raise ConfigError(node_ns, 'base_local_planner',
                          f"unknown planner '{mb['base_local_planner']}' (implemented: {', '.join(LOCAL_PLANNERS)})")
    frames = read_group(reader, node_ns, MOVE_BASE_DIRECT[:2])
    mb.update(read_group(reader, node_ns, [p for p in MOVE_BASE_CFG if p.name in (
        'planner_frequency', 'controller_frequency', 'planner_patience', 'controller_patience', 'max_planning_retries',
        'oscillation_timeout', 'oscillation_distance', 'make_plan_clear_costmap', 'make_plan_add_unreachable_goal')]))
    radii = read_group(reader, node_ns, MOVE_BASE_DIRECT[2:4])
    clearing = read_group(reader, node_ns, MOVE_BASE_DIRECT[4:5],
                          {'clearing_radius': radii['local_costmap/circumscribed_radius']})
    mb.update(read_group(reader, node_ns, [p for p in MOVE_BASE_CFG if p.name in (
        'conservative_reset_dist', 'shutdown_costmaps', 'clearing_rotation_allowed', 'recovery_behavior_enabled')]))
    if mb['controller_frequency'] <= 0:
        raise ConfigError(node_ns, 'controller_frequency', f"must be > 0, got {mb['controller_frequency']}")
    mbc = move_base_config(mb)

    global_costmap = read_costmap(reader, node_ns, 'global_costmap', warnings)
    planner_ns = _join(node_ns, mb['base_global_planner'].split('/')[-1])
    nav = read_group(reader, planner_ns, NAVFN_DIRECT)
    planner = PlannerConfig(allow_unknown=nav['allow_unknown'], default_tolerance=nav['default_tolerance'],
                            visualize_potential=nav['visualize_potential'],
                            planner_window_x=nav['planner_window_x'], planner_window_y=nav['planner_window_y'])

    local_costmap = read_costmap(reader, node_ns, 'local_costmap', warnings)
    dwa_ns = _join(node_ns, 'DWAPlannerROS')
    odom_topic = reader.get(_join(dwa_ns, 'odom_topic'), 'odom')
    if not isinstance(odom_topic, str) or not odom_topic:
        raise ConfigError(dwa_ns, 'odom_topic', f'expected a topic name, got {odom_topic!r}')
    for new, old in DWA_RENAMED:
        if reader.has(_join(dwa_ns, old)):
            warnings.append(f'{dwa_ns}: parameter {old} has been renamed to {new}, please update your config '
                            f'(the old name is ignored, as in DWAPlannerROS on Noetic)')
    found = reader.search(dwa_ns, 'controller_frequency')
    if found:
        freq = reader.get(found, 20.0)
        check_value(_d('controller_frequency', 20.0, '', 0), freq, dwa_ns)
    extra = read_group(reader, dwa_ns, DWA_DIRECT)
    dwa_values = read_group(reader, dwa_ns, DWA_CFG)
    for lo, hi in (('min_vel_x', 'max_vel_x'), ('min_vel_trans', 'max_vel_trans'), ('min_vel_theta', 'max_vel_theta')):
        if dwa_values[lo] > dwa_values[hi]:
            raise ConfigError(dwa_ns, lo, f'must be <= {hi} ({dwa_values[hi]}), got {dwa_values[lo]}')
    dwa = dwa_config(dwa_values, extra)

    recoveries = read_recoveries(reader, node_ns, mbc, radii['local_costmap/circumscribed_radius'])
    return NavigationParams(
        move_base=mbc, base_global_planner=mb['base_global_planner'], base_local_planner=mb['base_local_planner'],
        robot_base_frame=frames['global_costmap/robot_base_frame'], global_frame=frames['global_costmap/global_frame'],
        clearing_radius=clearing['clearing_radius'],
        circumscribed_radius=radii['local_costmap/circumscribed_radius'],
        global_costmap=global_costmap, local_costmap=local_costmap, planner=planner, dwa=dwa, dwa_extra=extra,
        odom_topic=odom_topic, recoveries=recoveries, warnings=warnings)


def generate_cfg(stem: str) -> int:
    """Body of ``cfg/<stem>.cfg``: declare the group :data:`RECONFIGURABLE` [stem] to dynamic_reconfigure.

    Runs at build time under catkin's dynamic_reconfigure macros (``generate_dynamic_reconfigure_options``).
    """
    from dynamic_reconfigure.parameter_generator_catkin import ParameterGenerator, bool_t, double_t, int_t, str_t
    params, node_name = RECONFIGURABLE[stem]
    types = {'double': double_t, 'int': int_t, 'bool': bool_t, 'str': str_t}
    gen = ParameterGenerator()
    for p in params:
        kw = {}
        if p.kind in ('double', 'int'):
            if p.minimum is not None:
                kw['min'] = int(p.minimum) if p.kind == 'int' else float(p.minimum)
            if p.maximum is not None:
                kw['max'] = int(p.maximum) if p.kind == 'int' else float(p.maximum)
        gen.add(p.name, types[p.kind], 0, p.description, p.default, **kw)
    return gen.generate('cnr_navigation', node_name, stem)


def markdown_tables() -> str:
    """The README's parameter tables, generated from the declarations above (one source of truth)."""
    groups = [
        ('~ (move_base, reconfigurable)', MOVE_BASE_CFG), ('~ (move_base, read once)', MOVE_BASE_DIRECT),
        ('~<costmap>/ (global_costmap, local_costmap; reconfigurable)', COSTMAP_CFG),
        ('~<costmap>/ (read once)', COSTMAP_DIRECT),
        ('~<costmap>/static_layer/ (reconfigurable)', GENERIC_PLUGIN_CFG),
        ('~<costmap>/static_layer/ (read once)', STATIC_DIRECT),
        ('~<costmap>/obstacle_layer/ (reconfigurable)', OBSTACLE_PLUGIN_CFG),
        ('~<costmap>/obstacle_layer/ (read once)', OBSTACLE_DIRECT),
        ('~<costmap>/obstacle_layer/<source>/', SOURCE_DIRECT + SOURCE_SEARCHED),
        ('~<costmap>/inflation_layer/ (reconfigurable)', INFLATION_PLUGIN_CFG),
        ('~NavfnROS/', NAVFN_DIRECT), ('~DWAPlannerROS/ (reconfigurable)', DWA_CFG),
        ('~DWAPlannerROS/ (read once)', DWA_DIRECT),
        ('~<recovery>/ (ClearCostmapRecovery)', CLEAR_RECOVERY_DIRECT),
        ('~<recovery>/ (RotateRecovery)', ROTATE_RECOVERY_DIRECT),
    ]
    out = []
    for title, params in groups:
        out += [f'#### `{title}`', '', '| parameter | type | default | range | description |', '|---|---|---|---|---|']
        for p in params:
            rng = '' if p.minimum is None and p.maximum is None else f'{p.minimum}..{p.maximum}'
            out.append(f'| `{p.name}` | {p.kind} | `{p.default!r}` | {rng} | {p.description} |')
        out.append('')
    return '\n'.join(out)
