"""The network-aware decision's settings from a :class:`cnr_params.Section` (config/decision.yaml, or a node's
private parameters loaded from it). No defaults here: a missing or bad parameter is a one-line ConfigError
naming the source and the field, e.g. ``config/decision.yaml: k: must be odd (...), got 4``."""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Dict, List, Tuple

from cnr_params import Section
from network_monitor.core.decision import ColdStartRule, DecisionSettings, Exploration, Normalisation
from network_monitor.core.evaluation import OFFLOAD, ONLOAD
from network_monitor.core.hysteresis import ReDecisionSettings
from network_monitor.core.training import TrainingSet, valid_name


@dataclass(frozen=True)
class DecisionConfig:
    training_dir: str                       # directory of the <task>@<location>.tsv sets (~ expanded)
    decision: DecisionSettings              # k, normalisation, cold start, exploration
    v_r: float                              # validity ratio of Eq. 4-5
    control_values: str                     # path of the control values YAML (may not exist yet)
    redecision: ReDecisionSettings
    robot_host: str                         # host names of a placement (config/placements.yaml hosts)
    cloud_host: str
    tasks: Dict[str, Tuple[str, ...]]       # task -> the modules its decision places
    locations: Tuple[str, ...]

    def placement(self, task: str, decision: str) -> str:
        """What ``decision`` places where for ``task``, e.g. ``mfg=cloud,global_goal_manager=cloud``."""
        if task not in self.tasks:
            raise ValueError(f'unknown task {task!r} (configured: {", ".join(self.tasks)})')
        host = {OFFLOAD: self.cloud_host, ONLOAD: self.robot_host}.get(decision)
        if host is None:
            raise ValueError(f'unknown decision {decision!r} (expected offload or onload)')
        return ','.join(f'{m}={host}' for m in self.tasks[task])

    def training_set(self, task: str, location: str) -> TrainingSet:
        """The training set of a configured ⟨task, location⟩."""
        if task not in self.tasks:
            raise ValueError(f'unknown task {task!r} (configured: {", ".join(self.tasks)})')
        if location not in self.locations:
            raise ValueError(f'unknown location {location!r} (configured: {", ".join(self.locations)})')
        return TrainingSet(self.training_dir, task, location)


def _name(s: Section, key: str) -> str:
    value = s.string(key)
    if not valid_name(value):
        raise s.error(key, f'must be a name (letters, digits, _ . -), got {value!r}')
    return value


def _names(s: Section, key: str, what: str) -> Tuple[str, ...]:
    value = s.raw(key)
    if not isinstance(value, list) or not value:
        raise s.error(key, f'expected a non-empty list of {what}, got {value!r}')
    out: List[str] = []
    for item in value:
        if not isinstance(item, str) or not valid_name(item):
            raise s.error(key, f'bad {what[:-1]} name {item!r} (letters, digits, _ . -)')
        if item in out:
            raise s.error(key, f'{item!r} listed twice')
        out.append(item)
    return tuple(out)


def decision_config(s: Section) -> DecisionConfig:
    """Validate every parameter; raises ConfigError naming the first bad one."""
    training_dir = s.string('training_dir')
    if not training_dir:
        raise s.error('training_dir', 'must not be empty')
    k = s.integer('k', minimum=1)
    if k % 2 == 0:
        raise s.error('k', f'must be odd (Eq. 4-4 is undefined at a tie of k/2 votes), got {k}')

    n = s.section('normalisation')
    norm = Normalisation(rtt_max=n.number('rtt_max', positive=True),
                         r_bw_min=n.number('r_bw_min', positive=True),
                         r_bw_max=n.number('r_bw_max', positive=True))
    if norm.r_bw_max <= norm.r_bw_min:
        raise n.error('r_bw_max', f'must be > r_bw_min ({norm.r_bw_min:g}), got {norm.r_bw_max:g}')

    c = s.section('cold_start')
    cold = ColdStartRule(rtt=c.number('rtt', positive=True), r_bw=c.number('r_bw', positive=True))

    e = s.section('exploration')
    seed = e.raw('seed')
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise e.error('seed', f'expected an integer or null, got {seed!r}')
    explore = Exploration(rate=e.number('rate', minimum=0.0, maximum=0.5),
                          max_rtt=e.number('max_rtt', positive=True), seed=seed)

    ev = s.section('evaluation')
    v_r = ev.number('v_r', positive=True)
    control = os.path.expanduser(ev.string('control_values'))
    if not control:
        raise ev.error('control_values', 'must not be empty')
    if not os.path.isabs(control) and os.path.isfile(s.source):
        control = os.path.join(os.path.dirname(os.path.abspath(s.source)), control)

    r = s.section('redecision')
    margin = r.number('margin', maximum=1.0)
    if not margin > 0.5:
        raise r.error('margin', f'must be > 0.5 (a majority for the other placement), got {margin:g}')
    clear = r.section('clear')
    clear_margin = clear.raw('margin')
    if clear_margin is not None:
        clear_margin = clear.number('margin', maximum=1.0)
        if clear_margin < margin:
            raise clear.error('margin', f'must be >= redecision.margin ({margin:g}), got {clear_margin:g}')
    redecision = ReDecisionSettings(margin=margin, dwell=r.number('dwell', nonnegative=True),
                                    max_migrations=r.integer('max_migrations', minimum=0),
                                    window=r.number('window', positive=True), clear_margin=clear_margin,
                                    clear_dwell=clear.number('dwell', nonnegative=True))

    robot_host, cloud_host = _name(s, 'robot_host'), _name(s, 'cloud_host')
    if robot_host == cloud_host:
        raise s.error('cloud_host', f'must differ from robot_host ({robot_host!r})')

    t = s.section('tasks')
    if not t.data:
        raise s.error('tasks', 'expected at least one task')
    tasks: Dict[str, Tuple[str, ...]] = {}
    for task in t.keys():
        if not isinstance(task, str) or not valid_name(task):
            raise t.error(str(task), 'bad task name (letters, digits, _ . -)')
        tasks[task] = _names(t.section(task), 'modules', 'modules')

    return DecisionConfig(training_dir=os.path.expanduser(training_dir),
                          decision=DecisionSettings(k=k, normalisation=norm, cold_start=cold, exploration=explore),
                          v_r=v_r, control_values=control, redecision=redecision, robot_host=robot_host,
                          cloud_host=cloud_host, tasks=tasks, locations=_names(s, 'locations', 'locations'))


def load_decision_config(path: str) -> DecisionConfig:
    """:func:`decision_config` of a YAML file."""
    return decision_config(Section.from_file(path))
