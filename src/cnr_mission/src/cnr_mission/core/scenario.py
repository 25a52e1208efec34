"""Scenario files: the whole file checked before anything is launched (ROS-free).

A scenario (``config/scenarios/*.yaml``) is loaded by mission.launch into several nodes' namespaces, each
after the node's own ``config/<node>.yaml``. :func:`validate_scenario` reads it exactly as those nodes will,
with their own parsers, so there is one rule per field:

* ``scenario``: ``name``, ``map`` (in the maps folder unless absolute; must load with map_server's rules),
  ``start`` [x m, y m, yaw rad] (inside the map, on a free map cell);
* ``mapcells``: local_mapcell_manager's grid (:func:`local_mapcell_manager.core.params.read_grid`, inside the map);
* ``temperature_field``: kestrel_driver's heat-source parser (:meth:`TemperatureField.from_section`);
* ``global_goal_manager`` and ``mfg``: the nodes' ``read_params`` over ``config/<node>.yaml`` with the
  scenario laid over it (as ``rosparam load`` does);
* ``mission``: mission_monitor's :func:`read_mission`.

Every problem raises :class:`cnr_params.ConfigError` naming the scenario file and the field.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Any, Dict

from cnr_maps.grid import MapcellGrid
from cnr_maps.mapio import OccupancyMap, load_map
from cnr_maps.pose import Pose2D
from cnr_params import ConfigError, Section, load_yaml
from global_goal_manager.core.policies import GoalManagerParams
from global_goal_manager.core.policies import read_params as read_goal_manager
from kestrel_driver.core.field import TemperatureField
from local_mapcell_manager.core.params import read_grid
from mfg.core.params import MfgParams
from mfg.core.params import read_params as read_mfg


@dataclass
class MissionSettings:
    extra_time: float        # s of sim time after the hotspot before the mission stops
    timeout: float           # s of sim time without a hotspot before it gives up


@dataclass
class Scenario:
    path: str
    name: str
    map_file: str            # absolute path of the map_server YAML
    start: Pose2D
    occupancy: OccupancyMap
    grid: MapcellGrid
    field: TemperatureField
    goals: GoalManagerParams
    mfg: MfgParams
    mission: MissionSettings


def read_mission(p: Section) -> MissionSettings:
    """mission_monitor's scenario settings: ``mission.extra_time``, ``mission.timeout`` (no defaults)."""
    m = p.section('mission')
    return MissionSettings(extra_time=m.number('extra_time', nonnegative=True),
                           timeout=m.number('timeout', positive=True))


def overlay(base: Dict[str, Any], top: Dict[str, Any]) -> Dict[str, Any]:
    """``top`` laid over ``base`` key by key, as successive ``rosparam load`` into one namespace do."""
    out = copy.deepcopy(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = overlay(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _read_map(s: Section, maps_dir: str) -> str:
    name = s.string('map')
    path = name if os.path.isabs(name) else os.path.join(maps_dir, name)
    if not os.path.isfile(path):
        raise s.error('map', f'file not found: {path}')
    path = os.path.abspath(path)
    if any(c.isspace() for c in path):
        raise s.error('map', f'path contains white space (cannot be passed to roslaunch): {path!r}')
    return path


def validate_scenario(path: str, config_dir: str, maps_dir: str) -> Scenario:
    """Read and check a whole scenario file.

    Args:
        path: the scenario YAML.
        config_dir: the folder of the nodes' default files (``config/``: mfg.yaml, global_goal_manager.yaml).
        maps_dir: the folder relative map names are resolved in (``maps/``).

    Raises:
        ConfigError: the first problem, naming ``path`` and the field.
    """
    data = load_yaml(path)
    sec = Section(data, path)
    s = sec.section('scenario')
    name = s.string('name')
    if not name or any(c.isspace() for c in name):
        raise s.error('name', f'must be one word (it names the report folder), got {name!r}')
    map_file = _read_map(s, maps_dir)
    try:
        occupancy = load_map(map_file)
    except ConfigError as exc:
        raise s.error('map', str(exc)) from None
    x, y, yaw = s.vector('start', 3)
    problem = occupancy.point_problem(x, y)
    if problem:
        raise s.error('start', f'({x:g}, {y:g}) is {problem} ({os.path.basename(map_file)})')
    grid = read_grid(sec, occupancy)
    field = TemperatureField.from_section(sec.section('temperature_field'))
    goals = read_goal_manager(Section(overlay(load_yaml(os.path.join(config_dir, 'global_goal_manager.yaml')), data),
                                      path))
    mfg = read_mfg(Section(overlay(load_yaml(os.path.join(config_dir, 'mfg.yaml')), data), path))
    mission = read_mission(sec)
    return Scenario(path=path, name=name, map_file=map_file, start=Pose2D(x, y, yaw), occupancy=occupancy,
                    grid=grid, field=field, goals=goals, mfg=mfg, mission=mission)
