"""Decision evaluation (thesis §4.2.6, Eq. 4-5), labelling, and the control values it compares against.

Eq. 4-5 compares a run's task time T_task [s] and battery use B_task [fraction of a full battery] with the
control values CT_task, CB_task (the means of a control experiment with every module on the robot)::

    value = ((T_task / CT_task) + (B_task / CB_task)) / 2        good  iff  value <= V_r

(V_r, the validity ratio: 1.05 lets a decision be 5 % worse than the control and still count as good.)

Labelling. The thesis evaluated only offload decisions, so its training set grew biased towards onloading
(§6.3). Here every run is labelled with the placement that *should* have been chosen, whichever was::

    decision  completed  value <= V_r   label
    offload   yes        yes            offload   (offload was best)
    offload   yes        no             onload    (onload would have been best)
    onload    yes        yes            onload    (onload was fine)
    onload    yes        no             offload   (the other placement would have been better)
    any       no         -              the other placement   (the mission failed with this one)

``good`` is 1 only for a completed mission within V_r. The k-NN trains on the labels.

Control values live in a YAML file (``config/control_values.yaml``) written by the control experiment
(:func:`write_control_values`), one entry per task::

    corridor_round_trip:
      ct_mean: 87.93      # s, mean task time with every module on the robot
      ct_std: 14.38       # s
      cb_mean: 0.004586   # battery fraction (0..1) used per task, mean
      cb_std: 0.000702
      runs: 20
      date: '2026-11-23T10:00:00+00:00'
      command: launch_scripts/exp_control.sh ...

No values ship with the code: :func:`load_control_values` raises a ConfigError naming the file if it is
missing, or the file and the task if the task has no entry.
"""
from __future__ import annotations

import datetime
import math
import os
from dataclasses import dataclass
from typing import Any, Dict

import yaml

from cnr_params import Section, load_yaml
from cnr_params.files import write_atomic

OFFLOAD = 'offload'
ONLOAD = 'onload'
DECISIONS = (OFFLOAD, ONLOAD)

COMPLETED = 'completed'     # the task ran to its normal end (every goal of it reached or given up by the task)
ABORTED = 'aborted'         # the task stopped before its end: a module failed (e.g. move_base aborted a goal,
                            # a module died, the link broke with a needed module on the cloud)
TIMED_OUT = 'timed_out'     # the task did not end within its time limit
MISSION_STATUSES = (COMPLETED, ABORTED, TIMED_OUT)


def other(decision: str) -> str:
    """The other placement: offload <-> onload."""
    if decision == OFFLOAD:
        return ONLOAD
    if decision == ONLOAD:
        return OFFLOAD
    raise ValueError(f'unknown decision {decision!r} (expected offload or onload)')


@dataclass(frozen=True)
class ControlValues:
    """One task's control values (every module on the robot)."""
    task: str
    ct_mean: float      # s
    ct_std: float       # s
    cb_mean: float      # battery fraction 0..1 per task
    cb_std: float
    runs: int
    date: str           # ISO 8601, when the control experiment ended
    command: str        # the command that produced them


@dataclass(frozen=True)
class Evaluation:
    value: float        # Eq. 4-5 left side (dimensionless, 1 = as good as the control on average)
    good: bool          # completed and value <= V_r
    label: str          # the placement that should have been chosen (offload|onload)


def evaluation_value(t_task: float, b_task: float, control: ControlValues) -> float:
    """Eq. 4-5's left side: ((T_task / CT_task) + (B_task / CB_task)) / 2.

    Args:
        t_task: task time [s].
        b_task: battery used by the task [fraction of a full battery]; may be slightly negative (batteries
            sometimes read higher after a task, thesis §5.2).
        control: the task's control values (ct_mean, cb_mean > 0).
    """
    if not (math.isfinite(t_task) and math.isfinite(b_task)):
        raise ValueError(f'T_task and B_task must be finite, got {t_task!r}, {b_task!r}')
    return (t_task / control.ct_mean + b_task / control.cb_mean) / 2.0


def label_for(decision: str, good: bool, mission_status: str) -> str:
    """The placement that should have been chosen (module docstring's table)."""
    if mission_status not in MISSION_STATUSES:
        raise ValueError(f'unknown mission status {mission_status!r} (expected {", ".join(MISSION_STATUSES)})')
    if mission_status != COMPLETED:
        return other(decision)
    return decision if good else other(decision)


def evaluate(decision: str, mission_status: str, t_task: float, b_task: float, control: ControlValues,
             v_r: float) -> Evaluation:
    """Value (Eq. 4-5), good (completed and value <= V_r) and label of one run."""
    value = evaluation_value(t_task, b_task, control)
    good = mission_status == COMPLETED and value <= v_r
    return Evaluation(value=value, good=good, label=label_for(decision, good, mission_status))


@dataclass(frozen=True)
class Outcome:
    """A measured run for the oracle: task time [s], battery fraction used, mission status."""
    t_task: float
    b_task: float
    mission_status: str


def better_placement(offload: Outcome, onload: Outcome, control: ControlValues) -> str:
    """Oracle for paired runs (the same condition run once per placement): the placement with the lower
    Eq. 4-5 value; a placement whose mission did not complete loses to one that did; equal values (or both
    failed) -> onload, the safe choice."""
    off_ok, on_ok = offload.mission_status == COMPLETED, onload.mission_status == COMPLETED
    if off_ok != on_ok:
        return OFFLOAD if off_ok else ONLOAD
    if not off_ok:
        return ONLOAD
    v_off = evaluation_value(offload.t_task, offload.b_task, control)
    v_on = evaluation_value(onload.t_task, onload.b_task, control)
    return OFFLOAD if v_off < v_on else ONLOAD


# ---------------------------------------------------------------- control values file
def _control_from_section(s: Section, task: str) -> ControlValues:
    date = s.raw('date')
    if isinstance(date, (datetime.date, datetime.datetime)):     # an unquoted YAML date
        date = date.isoformat()
    if not isinstance(date, str) or not date:
        raise s.error('date', f'expected an ISO 8601 date string, got {date!r}')
    return ControlValues(task=task,
                         ct_mean=s.number('ct_mean', positive=True),
                         ct_std=s.number('ct_std', nonnegative=True),
                         cb_mean=s.number('cb_mean', positive=True),
                         cb_std=s.number('cb_std', nonnegative=True),
                         runs=s.integer('runs', minimum=1),
                         date=date,
                         command=s.string('command'))


def load_control_values(path: str, task: str) -> ControlValues:
    """The control values of ``task`` from ``path``.

    Raises:
        ConfigError: the file is missing or malformed (naming the file), the task has no entry, or a field is
            missing or invalid (naming the file and ``task.field``).
    """
    s = Section.from_file(path)
    if task not in s:
        raise s.error(task, 'no control values for this task (run the control experiment: exp_control.sh)')
    return _control_from_section(s.section(task), task)


def write_control_values(path: str, values: ControlValues) -> None:
    """Set ``values.task``'s entry in ``path`` (other tasks kept), atomically (temporary file + rename).

    Raises:
        ConfigError: an existing file is malformed; or a value is invalid (checked as the loader would).
    """
    entry: Dict[str, Any] = {'ct_mean': float(values.ct_mean), 'ct_std': float(values.ct_std),
                             'cb_mean': float(values.cb_mean), 'cb_std': float(values.cb_std),
                             'runs': int(values.runs), 'date': str(values.date), 'command': str(values.command)}
    _control_from_section(Section(entry, path, values.task), values.task)      # validate before writing
    data: Dict[str, Any] = load_yaml(path) if os.path.exists(path) else {}
    data[values.task] = entry
    text = ('# Control values for Eq. 4-5 (thesis §4.2.6, Table 4-5): every module on the robot, per task.\n'
            '# Written by the control experiment (exp_control.sh); ct in s, cb in battery fraction (0..1).\n'
            + yaml.safe_dump(dict(sorted(data.items())), default_flow_style=False, sort_keys=False))
    write_atomic(path, text, durable=True)

