"""Reading move_base's parameter tree one parameter at a time, validated (ROS-free).

:func:`read_navigation_params` reads the whole tree through a :class:`ParamReader`, one
``getParam`` / ``hasParam`` / ``searchParam`` / ``setParam`` per value, in the order of move_base,
costmap_2d, navfn, dwa_local_planner and the recoveries (navigation@noetic-devel). A move_base start-up
costs the master one XML-RPC call per value, and a later experiment measures that start-up, so it is
reproduced rather than replaced by one ``getParam('~')``. Every value is validated; a bad one raises
:class:`cnr_params.ConfigError` naming the parameter. The declarations are in
:mod:`cnr_navigation.core.param_tables`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Dict, List, Optional, Protocol, Sequence, Tuple

from cnr_params import ConfigError

from cnr_navigation.core.costmap import CostmapConfig, InflationLayerConfig, ObstacleLayerConfig, StaticLayerConfig
from cnr_navigation.core.dwa import DWAConfig
from cnr_navigation.core.move_base import MoveBaseConfig, RecoverySpec, default_recovery_specs
from cnr_navigation.core.param_tables import (
    CLEAR_RECOVERY_DIRECT, COSTMAP_CFG, COSTMAP_DIRECT, DWA_CFG, DWA_DIRECT, DWA_RENAMED, GENERIC_PLUGIN_CFG,
    GLOBAL_PLANNERS, INFLATION_PLUGIN_CFG, LOCAL_PLANNERS, MOVE_BASE_CFG, MOVE_BASE_DIRECT, NAVFN_DIRECT,
    OBSTACLE_DIRECT, OBSTACLE_PLUGIN_CFG, PLUGIN_TYPES, ROTATE_BLP, ROTATE_RECOVERY_DIRECT, SOURCE_DIRECT,
    SOURCE_DATA_TYPES, SOURCE_SEARCHED, STATIC_DIRECT, ClearTypes, Param, RotateTypes, _ROBOT_RADIUS,
    CONTROLLER_FREQUENCY, ROTATE_BLP_TOLERANCE)
from cnr_navigation.core.planner import PlannerConfig
from cnr_navigation.core.recovery import ClearCostmapConfig, RotateConfig


class ParamReader(Protocol):
    """One master call per method call (rospy in the node, a dict in tests). Names are absolute."""

    def get(self, name: str) -> Any:
        """getParam; raises :class:`cnr_params.ConfigError` naming the parameter when it is not set."""

    def get_optional(self, name: str) -> Optional[Any]:
        """getParam; None when the parameter is not set (for parameters whose absence has a meaning)."""

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


def missing(name: str) -> ConfigError:
    """The error for a parameter that is not set: ``<namespace>: <key>: missing``."""
    ns, _, key = name.rstrip('/').rpartition('/')
    return ConfigError(ns or '/', key, 'missing')


def read_group(reader: ParamReader, ns: str, params: Sequence[Param]) -> Dict[str, Any]:
    """Read each parameter of ``params`` under ``ns`` with one getParam, validated; every one is required."""
    return {p.name: check_value(p, reader.get(_join(ns, p.name)), ns) for p in params}


@dataclass
class SourceParams:
    """One observation source of an obstacle layer."""

    name: str
    data_type: str                            # one of SOURCE_DATA_TYPES
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
        raw = reader.get(_join(ns, 'plugins'))
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
            s = read_group(reader, pns, STATIC_DIRECT)
            g = read_group(reader, pns, GENERIC_PLUGIN_CFG)
            map_topic, first_map_only = s['map_topic'], s['first_map_only']
            static_cfg = StaticLayerConfig(enabled=g['enabled'], track_unknown_space=s['track_unknown_space'],
                                           lethal_cost_threshold=s['lethal_cost_threshold'],
                                           unknown_cost_value=s['unknown_cost_value'],
                                           trinary_costmap=s['trinary_costmap'], use_maximum=s['use_maximum'])
        elif kind == 'obstacle':
            o = read_group(reader, pns, OBSTACLE_DIRECT)
            names = o['observation_sources'].split()
            read_sources = []
            for src in names:
                sns = _join(pns, src)
                sp = read_group(reader, sns, SOURCE_DIRECT)
                if sp['data_type'] not in SOURCE_DATA_TYPES:
                    raise ConfigError(sns, 'data_type', f"unsupported '{sp['data_type']}' (expected one of: "
                                                        f"{', '.join(SOURCE_DATA_TYPES)})")
                for p in SOURCE_SEARCHED:
                    found = reader.search(sns, p.name)
                    if not found:
                        raise ConfigError(sns, p.name, 'missing (searched upwards from here)')
                    sp[p.name] = check_value(p, reader.get(found), sns)
                read_sources.append((src, sp))
            r = read_group(reader, pns, OBSTACLE_PLUGIN_CFG)
            if not read_sources:
                raise ConfigError(pns, 'observation_sources', 'no observation source (at least one is needed)')
            for src, sp in read_sources:
                sources.append(SourceParams(src, sp['data_type'], sp['topic'], sp['sensor_frame'],
                                            sp['expected_update_rate'],
                                            ObstacleLayerConfig(
                                                enabled=r['enabled'],
                                                footprint_clearing_enabled=r['footprint_clearing_enabled'],
                                                combination_method=r['combination_method'],
                                                track_unknown_space=o['track_unknown_space'],
                                                obstacle_range=sp['obstacle_range'],
                                                raytrace_range=sp['raytrace_range'],
                                                min_obstacle_height=sp['min_obstacle_height'],
                                                max_obstacle_height=sp['max_obstacle_height'],
                                                inf_is_valid=sp['inf_is_valid'], marking=sp['marking'],
                                                clearing=sp['clearing'])))
            obstacle_cfg = replace(sources[0].layer, max_obstacle_height=min(sources[0].layer.max_obstacle_height,
                                                                              r['max_obstacle_height']))
        else:
            r = read_group(reader, pns, INFLATION_PLUGIN_CFG)
            inflation_cfg = InflationLayerConfig(enabled=r['enabled'], inflation_radius=r['inflation_radius'],
                                                 cost_scaling_factor=r['cost_scaling_factor'],
                                                 inflate_unknown=r['inflate_unknown'])
    # makeFootprintFromParams: footprint, else robot_radius, each searched upwards
    footprint: List[Tuple[float, float]] = []
    found = reader.search(ns, 'footprint')
    if found:
        footprint = parse_footprint(reader.get(found), ns)
    if not footprint:
        found = reader.search(ns, 'robot_radius')
        if not found:
            raise ConfigError(ns, 'robot_radius', 'missing (searched upwards from here; or set a footprint)')
        radius = check_value(_ROBOT_RADIUS, reader.get(found), ns)
    else:
        radius = max(math.hypot(x, y) for x, y in footprint)
        warnings.append(f'{ns}: polygon footprint approximated by its circumscribed circle (r = {radius:.3f} m)')
    r = read_group(reader, ns, COSTMAP_CFG)
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
    raw = reader.get_optional(_join(node_ns, 'recovery_behaviors'))
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
            layers = reader.get(_join(rns, 'layer_names'))
            if not isinstance(layers, list) or not all(isinstance(v, str) for v in layers):
                raise ConfigError(rns, 'layer_names', f'expected a list of layer names, got {layers!r}')
            out.append(RecoveryParams(spec.name, spec.type, clear=ClearCostmapConfig(
                reset_distance=r['reset_distance'], affected_maps=r['affected_maps'], layer_names=list(layers),
                invert_area_to_clear=r['invert_area_to_clear'], force_updating=r['force_updating'])))
        else:
            r = read_group(reader, rns, ROTATE_RECOVERY_DIRECT)
            blp = _join(node_ns, 'TrajectoryPlannerROS')
            values = {}
            for p, old in ROTATE_BLP:
                if reader.has(_join(blp, p.name)):
                    values[p.name] = check_value(p, reader.get(_join(blp, p.name)), blp)
                elif reader.has(_join(blp, old)):
                    values[p.name] = check_value(p, reader.get(_join(blp, old)), blp)
                else:
                    raise ConfigError(blp, p.name, f'missing (or its old name {old})')
            tol = check_value(ROTATE_BLP_TOLERANCE, reader.get(_join(blp, ROTATE_BLP_TOLERANCE.name)), blp)
            out.append(RecoveryParams(spec.name, spec.type, rotate=RotateConfig(
                sim_granularity=r['sim_granularity'], frequency=r['frequency'], acc_lim_th=values['acc_lim_theta'],
                max_rotational_vel=values['max_vel_theta'],
                min_in_place_rotational_vel=values['min_in_place_vel_theta'], yaw_goal_tolerance=tol)))
    return out


def dwa_config(values: Dict[str, Any], extra: Dict[str, Any]) -> DWAConfig:
    """A :class:`DWAConfig` from the DWAPlanner.cfg group plus the direct reads."""
    names = {f for f in DWAConfig.__dataclass_fields__}
    kwargs = {k: v for k, v in values.items() if k in names}
    kwargs['latch_xy_goal_tolerance'] = extra['latch_xy_goal_tolerance']
    kwargs['cheat_factor'] = extra['cheat_factor']
    kwargs['sum_scores'] = extra['sum_scores']
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
    clearing = read_group(reader, node_ns, MOVE_BASE_DIRECT[4:5])
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
    odom_topic = reader.get(_join(dwa_ns, 'odom_topic'))
    if not isinstance(odom_topic, str) or not odom_topic:
        raise ConfigError(dwa_ns, 'odom_topic', f'expected a topic name, got {odom_topic!r}')
    for new, old in DWA_RENAMED:
        if reader.has(_join(dwa_ns, old)):
            warnings.append(f'{dwa_ns}: parameter {old} has been renamed to {new}, please update your config '
                            f'(the old name is ignored, as in DWAPlannerROS on Noetic)')
    found = reader.search(dwa_ns, 'controller_frequency')
    if found:
        check_value(CONTROLLER_FREQUENCY, reader.get(found), dwa_ns)
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
