"""Tasks the network-aware decision is made for (thesis §3.4.1, §4.2.3), and run plans of many of them (no ROS).

A task is a fixed piece of work with a start and an end, measured by its time T_task and the battery it used
B_task. Its definition lives in the location's scenario file (config/scenarios/<location>.yaml, ``tasks``)::

    tasks:
      corridor_round_trip:               # the thesis's task: to the end of the corridor and back
        start: [0.5, 0.0, 0.0]           # m, m, rad: the robot is put here before each run
        goals: [[4.5, 0.0, 0.0], [0.5, 0.0, 3.14159]]   # move_base goals in the map frame, in order
        goal_timeout: 90.0               # s of sim time per goal before the task counts as timed out

Mission status (the thesis never defines it; :func:`mission_status`): ``completed`` when move_base reached
every goal; ``aborted`` when move_base gave up on one (ABORTED/REJECTED/LOST, or its action server was gone
for longer than the runner's ``server_timeout``); ``timed_out`` when a goal took longer than ``goal_timeout``.

A *plan* (YAML) lists runs for the ``task_runner`` node; each has an id, the link to set before it (optional),
and what to decide (``force``: '' = the migration_decider decides, offload | onload = that placement;
``other`` = the other placement than the previous run of the same condition ran, for paired runs;
``decide: false`` = no decider at all, e.g. the control runs; ``learn``: append the evaluated row to the
training set; ``explore``: the decision may explore; ``reuse_profile``: decide on the previous run's profile,
e.g. the second run of a pair under the same link; ``task``: this run's task, default the plan's ``task``, so one
session can alternate tasks). Results are appended to a TSV, one row per run, its task in the ``task`` column,
so a plan that was interrupted resumes after its last finished run (:func:`read_results`).

B_task is the robot computer's battery (the netbook's pack, as the thesis read BAT0); ``b_base`` beside it in a
row is the same fraction of the Kobuki base's pack over the drive (recorded, never evaluated). A decided run's
T_task and B_task count its placement too (a migration before the drive is part of running there: Eq. 4-5 and
the label weigh it); ``t_decision`` and ``b_decision`` in the row are the whole decision's cost, its profile (the
probe included; the same for either placement) and the placement. Each pack's percentage at an instant is read
between its two readings around it (:func:`charge_at`; the simulator publishes them at 1 Hz). A results file without the later columns
(:data:`LATER_COLUMNS`; e.g. :data:`RESULT_COLUMNS_ONE_PACK`) is read and appended to in its own columns.
"""
from __future__ import annotations

import bisect
import math
import os
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Set, Tuple

from cnr_params import ConfigError, Section

OTHER = 'other'             # force: the other placement than the previous run of the same condition (paired runs)
FORCE = ('', 'offload', 'onload', OTHER)
COMPLETED, ABORTED, TIMED_OUT = 'completed', 'aborted', 'timed_out'
SUCCEEDED, GAVE_UP, TOO_LONG = 'succeeded', 'gave_up', 'too_long'       # one goal's outcome


@dataclass(frozen=True)
class TaskSpec:
    name: str
    start: Tuple[float, float, float]
    goals: Tuple[Tuple[float, float, float], ...]
    goal_timeout: float


def _pose(s: Section, key: str, value) -> Tuple[float, float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 3 and
            all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise s.error(key, f'expected [x, y, yaw] (m, m, rad), got {value!r}')
    return float(value[0]), float(value[1]), float(value[2])


def load_task(scenario: Section, name: str) -> TaskSpec:
    """The task ``name`` of a scenario file's ``tasks`` section (ConfigError naming the file and field)."""
    tasks = scenario.section('tasks')
    if name not in tasks:
        raise tasks.error(name, f'no such task (defined: {", ".join(map(str, tasks.keys())) or "none"})')
    t = tasks.section(name)
    goals = t.raw('goals')
    if not isinstance(goals, list) or not goals:
        raise t.error('goals', f'expected a non-empty list of [x, y, yaw], got {goals!r}')
    return TaskSpec(name=name, start=_pose(t, 'start', t.raw('start')),
                    goals=tuple(_pose(t, f'goals[{i}]', g) for i, g in enumerate(goals)),
                    goal_timeout=t.number('goal_timeout', positive=True))


def mission_status(outcomes: Sequence[str], goals: int) -> str:
    """The task's status from its goals' outcomes (module docstring)."""
    for o in outcomes:
        if o == GAVE_UP:
            return ABORTED
        if o == TOO_LONG:
            return TIMED_OUT
        if o != SUCCEEDED:
            raise ValueError(f'unknown goal outcome {o!r}')
    return COMPLETED if len(outcomes) == goals else ABORTED


def battery_used(percentage_before: Optional[float], percentage_after: Optional[float]) -> float:
    """B_task: the fraction of a full battery used, from two sensor_msgs/BatteryState ``percentage`` readings
    (ROS: 0..1); NaN when a reading is missing (no BatteryState arrived) or not finite — such a run has no B_task
    and must not be evaluated or learned (:func:`evaluable`)."""
    if percentage_before is None or percentage_after is None:
        return math.nan
    return percentage_before - percentage_after


def battery_fields(computer: Tuple[Optional[float], Optional[float]],
                   base: Tuple[Optional[float], Optional[float]], decided: bool = False,
                   at_placing: Optional[float] = None, at_profile: Optional[float] = None) -> Dict[str, float]:
    """A run's battery columns from the percentages (before, after) of each pack over the drive: ``b_task``
    (Eq. 4-5) the robot computer's, ``b_base`` the base's (:func:`battery_used`). A ``decided`` run's ``b_task``
    counts from ``at_placing``, the computer's percentage when the placement began, and ``b_decision`` is the
    computer's from ``at_profile``, when the decision's profile began, to the drive (module docstring); NaN without
    a reading."""
    fields = dict(b_task=battery_used(*computer), b_base=battery_used(*base))
    if decided:
        fields.update(b_task=battery_used(at_placing, computer[1]), b_decision=battery_used(at_profile, computer[0]))
    return fields


def charge_at(readings: Sequence[Tuple[float, float]], t: float) -> Optional[float]:
    """A pack's percentage at time ``t`` from its readings (time, percentage), in time order: linear between the
    two around ``t``; the last one's after it (the next has not come); None before the first (no reading yet)."""
    i = bisect.bisect_right([r[0] for r in readings], t)
    if i == 0:
        return None
    if i == len(readings):
        return readings[-1][1]
    (ta, pa), (tb, pb) = readings[i - 1], readings[i]
    return pa if tb <= ta else pa + (pb - pa) * (t - ta) / (tb - ta)


def evaluable(b_task: float) -> bool:
    """Whether a run's B_task is a measurement (a run without one is invalid: never labelled, never learned)."""
    return math.isfinite(b_task)


# ---------------------------------------------------------------- plans
@dataclass(frozen=True)
class Link:
    delay: float            # one-way delay per direction [ms]
    rate: float             # per direction [Mbit/s], 0 = unlimited
    loss: float             # per direction [0..1]

    @property
    def rtt_ms(self) -> float:
        return 2.0 * self.delay


@dataclass(frozen=True)
class RunSpec:
    id: str
    condition: str          # runs of one condition share it (paired runs)
    link: Optional[Link]    # None: leave the link as it is
    force: str              # '' | offload | onload | other
    decide: bool            # ask the migration_decider (False: run as placed, no evaluation)
    learn: bool             # the decider appends the evaluated row to the training set
    explore: bool           # the decision may explore (False: the k-NN's or the rule's choice)
    reuse_profile: bool     # decide on the previous run's profile (paired runs under one link)
    task: str = ''          # this run's task ('' = the plan's)


@dataclass(frozen=True)
class Plan:
    task: str
    location: str
    settle: float           # s after setting the link before profiling (the monitor's window fills)
    runs: Tuple[RunSpec, ...]

    def task_of(self, run: RunSpec) -> str:
        """The task a run of this plan runs."""
        return run.task or self.task

    @property
    def tasks(self) -> List[str]:
        """Every task the plan runs, in order of its first run."""
        return list(dict.fromkeys(self.task_of(r) for r in self.runs))


def _link(s: Section) -> Link:
    return Link(delay=s.number('delay', nonnegative=True), rate=s.number('rate', nonnegative=True),
                loss=s.number('loss', minimum=0.0, maximum=1.0))


def load_plan(path: str) -> Plan:
    """A plan file (module docstring); ConfigError naming the file and field."""
    s = Section.from_file(path)
    runs: List[RunSpec] = []
    seen: Set[str] = set()
    for i, r in enumerate(s.sections('runs')):
        rid = r.string('id')
        if not rid or '\t' in rid or rid in seen:
            raise r.error('id', f'must be a unique non-empty name, got {rid!r}')
        seen.add(rid)
        force = r.string('force')
        if force not in FORCE:
            raise r.error('force', f"expected '', offload, onload or other, got {force!r}")
        if force == OTHER and not any(x.condition == r.raw('condition', None) for x in runs):
            raise r.error('force', 'other needs an earlier run of the same condition')
        link = _link(r.section('link')) if r.raw('link', None) is not None else None
        task = r.string('task') if r.raw('task', None) is not None else ''
        if r.boolean('reuse_profile') and runs and runs[-1].task != task:
            raise r.error('reuse_profile', 'the previous run is of another task')
        runs.append(RunSpec(id=rid, condition=r.string('condition'), link=link, force=force,
                            decide=r.boolean('decide'), learn=r.boolean('learn'), explore=r.boolean('explore'),
                            reuse_profile=r.boolean('reuse_profile'), task=task))
    if not runs:
        raise s.error('runs', 'expected at least one run')
    return Plan(task=s.string('task'), location=s.string('location'), settle=s.number('settle', nonnegative=True),
                runs=tuple(runs))


RESULT_COLUMNS = ('id', 'condition', 'rtt_ms', 'rate_mbit', 'loss', 'force', 'decision', 'reason', 'policy',
                  'confidence', 'votes_offload', 'c_l', 'r_bw', 'profile_method', 'placed', 'placing_time',
                  'redecisions', 'placement', 'mission_status', 't_task', 'b_task', 'b_base', 't_decision',
                  'b_decision', 'value', 'good', 'label', 'learned', 'wall_start', 'wall_time', 'task')
#: columns a results file made before them lacks: read as '', appended to in the file's own columns
LATER_COLUMNS = ('b_base', 't_decision', 'b_decision', 'task')
#: the columns of a results file that records one battery pack and the task alone
RESULT_COLUMNS_ONE_PACK = tuple(c for c in RESULT_COLUMNS if c not in LATER_COLUMNS)


def _columns(path: str, header: str) -> Tuple[str, ...]:
    """The columns a results file's header line names (ConfigError if it is not a results file's):
    :data:`RESULT_COLUMNS`, or those less some of :data:`LATER_COLUMNS`."""
    columns = tuple(header.rstrip('\n').split('\t'))
    if columns != tuple(c for c in RESULT_COLUMNS if c in columns or c not in LATER_COLUMNS):
        raise ConfigError(path, 'header', 'not a task results file (unexpected header)')
    return columns


def _fmt(v) -> str:
    if isinstance(v, bool):
        return '1' if v else '0'
    if isinstance(v, float):
        return repr(v)
    return str(v).replace('\t', ' ').replace('\n', ' ')


def append_result(path: str, values: Dict) -> None:
    """Append one run's row to the results TSV (header first if the file is new; an existing file's columns,
    :func:`_columns`), flushed to disk. A file that does not end with a newline (a torn last line) gets one
    first, so only that line is lost. The file's folder is made if missing (a task's first run)."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    new = not os.path.exists(path) or os.path.getsize(path) == 0
    columns = RESULT_COLUMNS
    with open(path, 'a+b') as f:
        if not new:
            f.seek(0)
            columns = _columns(path, f.readline().decode('utf-8', errors='replace'))
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b'\n':
                f.write(b'\n')
        text = ('\t'.join(columns) + '\n' if new else '') + \
            '\t'.join(_fmt(values.get(c, '')) for c in columns) + '\n'
        f.write(text.encode())
        f.flush()
        os.fsync(f.fileno())


def read_results(path: str) -> Tuple[List[Dict[str, str]], List[str]]:
    """Rows of a results TSV as dicts of strings with every column of :data:`RESULT_COLUMNS` (those the file does
    not have: ''), and warnings (file:line) for lines that are not whole rows."""
    if not os.path.exists(path):
        return [], []
    rows, warnings = [], []
    with open(path, encoding='utf-8', errors='replace') as f:
        lines = f.read().split('\n')
    columns = _columns(path, lines[0])
    for n, line in enumerate(lines[1:], start=2):
        if not line:
            continue
        fields = line.split('\t')
        if len(fields) != len(columns):
            warnings.append(f'{path}:{n}: {len(fields)} fields, expected {len(columns)} (skipped)')
            continue
        rows.append(dict(dict.fromkeys(RESULT_COLUMNS, ''), **dict(zip(columns, fields))))
    return rows, warnings


def resolve_force(force: str, previous: Optional[str]) -> str:
    """The placement a run forces: ``other`` becomes the other one than ``previous`` (the decision of the
    previous run of the same condition)."""
    if force != OTHER:
        return force
    if previous not in ('offload', 'onload'):
        raise ValueError(f'force other: the previous run of the condition has no decision ({previous!r})')
    return 'onload' if previous == 'offload' else 'offload'
