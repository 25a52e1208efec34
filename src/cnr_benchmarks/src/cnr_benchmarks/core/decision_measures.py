"""The learned decision's measures on a campaign's held-out conditions (``campaign_summary.json``), without ROS.

Trials. A *trial* is one ⟨task, condition⟩ with every run of each placement that was made (a campaign may repeat a
placement under one link); its profile (C_l, R_bw) is its first run's, what a decision before the task knows. The
trials of each task are split in order as the learning curve splits its pairs: the last ``test_fraction`` are held
out.

Values. A completed run's value is Eq. 4-5's (evaluation.evaluation_value). A run that did not complete has no such
value; it is counted as the task done again in the other placement (the mean value of that placement's completed
runs, the control's 1 if none completed) plus :data:`FAILED_ATTEMPT` for the lost attempt, so a failure always
costs more than the other placement's success, whatever its own partial time and battery were.

Noise-aware oracle (:func:`trial_oracle`). The placement whose runs completed more often wins (a failing placement
loses, as evaluation.better_placement); with equal completion, the lower mean value of the completed runs wins,
unless the two means differ by no more than twice the standard error of their difference: then the trial is
EITHER and any decision is right for it. A placement's sd is its repeats' sample sd (>= 2 completed runs), else
what the control runs' spread gives a single run (core.campaign.noise_tolerance): with one run per placement this
is exactly core.campaign.oracle's noise-aware tolerance. With ``noise_aware=False`` every trial has a winner.

Regret. For a policy's choice in a trial: 0 when the noise-aware oracle agrees with it, else the chosen
placement's value minus the oracle's (:func:`placement_value`); a policy's regret is the mean over the held-out
trials. The a-priori rules are fixed before any data: always onload, always offload, the robot's cold-start rule
(config/decision.yaml ``cold_start``) and "offload iff RTT < 50 ms", on the trial's profile.

Thresholds. "Offload iff C_l < a and R_bw > b" (core.campaign.static_rule) fitted in hindsight on the held-out
trials' noise-aware labels: the best single pair for all tasks alike, and per task. The k-NN is the robot's own
(network_monitor.core.decision.Decider, no exploration) trained on at most ``max_rows`` of the task's training rows,
the first ones as the robot learned them.

Summary (:data:`SUMMARY_KEYS`, :func:`measures`): ``offload_better_share`` is the strict oracle's share of all the
trials; ``knn_noise_aware_accuracy_40`` the k-NN's agreement with the noise-aware oracle over every task's held-out
trials (per task under ``per_task``, with the task's a-priori regrets and its own hindsight threshold);
``knn_minus_best_single_threshold_pts`` that accuracy minus the single hindsight threshold's, in points; the
crossings, the good-link changes and the hours are the analysis's (:class:`Figures`). A value the trials cannot
give is None (JSON null), with a one-line reason in ``Measures.why_null``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Set, Tuple

import numpy as np

from cnr_benchmarks.core.campaign import EITHER, Threshold, agrees, best_threshold, held_out, noise_tolerance, number
from network_monitor.core.decision import Decider, DecisionSettings, Exploration
from network_monitor.core.evaluation import COMPLETED, OFFLOAD, ONLOAD, ControlValues, Outcome, evaluation_value
from network_monitor.core.training import Row

FAILED_ATTEMPT = 1.0            # Eq. 4-5 value of a lost attempt (one control task's worth) on top of its redo
A_PRIORI_RTT = 0.05             # s: "offload iff RTT < 50 ms" (FogROS2-LS-like systems)
MAX_ROWS = 40                   # the k-NN's training rows per task for the accuracy goal

ALWAYS_ONLOAD = 'always onload'
ALWAYS_OFFLOAD = 'always offload'
COLD_START_RULE = 'cold-start rule'
RTT_RULE = 'offload iff RTT < 50 ms'

# the keys of campaign_summary.json, in order (null where the data cannot give a value)
SUMMARY_KEYS = ('offload_better_share', 'tasks', 'training_conditions', 'knn_noise_aware_accuracy_40', 'regret_knn',
                'regret_best_a_priori', 'best_a_priori_rule', 'knn_minus_best_single_threshold_pts', 'crossing_rbw',
                'crossing_rbw_with_migration', 'crossing_rtt_ms', 'move_base_fails_rtt_ms',
                'good_link_time_change_pct', 'good_link_battery_change_pct', 'hours')


@dataclass(frozen=True)
class Trial:
    task: str
    condition: str
    rtt_ms: float               # the link's drawn RTT
    c_l: float                  # the profile before the task (its first run's): RTT [s]
    r_bw: float
    offload: Tuple[Outcome, ...]
    onload: Tuple[Outcome, ...]


def learned_during(learned: Sequence[Row], rows: Sequence[Mapping[str, str]], keys: Set[Tuple[str, str]],
                   default_task: str) -> List[Row]:
    """The training rows learned during the runs of the ⟨task, condition⟩s ``keys``, in order: each row's timestamp
    falls in its run's wall-clock span (a result row's task is its ``task`` field, ``default_task`` without one)."""
    spans = [(number(r, 'wall_start'), number(r, 'wall_start') + number(r, 'wall_time'),
              (r.get('task') or default_task, r['condition'])) for r in rows]

    def run_of(t: Row) -> Tuple[str, str]:
        return next((key for a, b, key in spans if a <= t.timestamp <= b + 1.0 and key[0] == t.task), ('', ''))
    return [t for t in learned if run_of(t) in keys]


def trials(rows: Sequence[Mapping[str, str]], default_task: str) -> List[Trial]:
    """The ⟨task, condition⟩s with at least one made run of each placement, in order of their first run. A row's
    task is its ``task`` field, ``default_task`` without one; a run whose placement was not made (``placed`` 0)
    measured nothing and is left out, as core.campaign.pairs does."""
    by: Dict[Tuple[str, str], List[Mapping[str, str]]] = {}
    for r in rows:
        by.setdefault((r.get('task') or default_task, r['condition']), []).append(r)
    out = []
    for (task, condition), runs in by.items():
        made = [r for r in runs if r.get('decision') in (OFFLOAD, ONLOAD) and r.get('placed') != '0']
        off = tuple(Outcome(number(r, 't_task'), number(r, 'b_task'), r['mission_status']) for r in made
                    if r['decision'] == OFFLOAD)
        on = tuple(Outcome(number(r, 't_task'), number(r, 'b_task'), r['mission_status']) for r in made
                   if r['decision'] == ONLOAD)
        if off and on:
            first = runs[0]
            out.append(Trial(task, condition, number(first, 'rtt_ms'), number(first, 'c_l'), number(first, 'r_bw'), off, on))
    return out


def split(ts: Sequence[Trial], test_fraction: float) -> Tuple[List[Trial], List[Trial]]:
    """(training, held-out): a learning plan's held-out conditions (core.campaign.held_out) are held out and the
    other trials train; else, per task, the last ``round(n * test_fraction)`` of its trials are held out."""
    if any(held_out(t.condition) for t in ts):
        return [t for t in ts if not held_out(t.condition)], [t for t in ts if held_out(t.condition)]
    train: List[Trial] = []
    held: List[Trial] = []
    for task in tasks_of(ts):
        mine = [t for t in ts if t.task == task]
        n_test = int(round(len(mine) * test_fraction))
        train += mine[:len(mine) - n_test]
        held += mine[len(mine) - n_test:]
    return train, held


def training_keys(rows: Sequence[Mapping[str, str]], ts: Sequence[Trial], test_fraction: float,
                  default_task: str) -> List[Tuple[str, str]]:
    """The ⟨task, condition⟩s the robot learned from, in order: in a learning plan every condition that is not held
    out (each ran once, in the placement the robot chose: not a trial), else the training trials (:func:`split`)."""
    keys = [(r.get('task') or default_task, r['condition']) for r in rows]
    if any(held_out(c) for _, c in keys):
        return list(dict.fromkeys(k for k in keys if not held_out(k[1])))
    return [(t.task, t.condition) for t in split(ts, test_fraction)[0]]


def tasks_of(ts: Sequence[Trial]) -> List[str]:
    """The trials' tasks in order of appearance."""
    return list(dict.fromkeys(t.task for t in ts))


def _completed_values(outcomes: Sequence[Outcome], control: ControlValues) -> List[float]:
    return [evaluation_value(o.t_task, o.b_task, control) for o in outcomes if o.mission_status == COMPLETED]


def placement_value(mine: Sequence[Outcome], other: Sequence[Outcome], control: ControlValues) -> float:
    """The mean value of one placement's runs: Eq. 4-5 for a completed run; for one that did not complete, the
    other placement's completed mean (1, the control's, if none) plus :data:`FAILED_ATTEMPT` (module docstring)."""
    redo = _completed_values(other, control)
    failed = (float(np.mean(redo)) if redo else 1.0) + FAILED_ATTEMPT
    values = [evaluation_value(o.t_task, o.b_task, control) if o.mission_status == COMPLETED else failed
              for o in mine]
    return float(np.mean(values))


def single_run_sd(control: ControlValues) -> float:
    """The sd of one run's Eq. 4-5 value by the control runs' spread (core.campaign.noise_tolerance's)."""
    return noise_tolerance(control) / (2.0 * math.sqrt(2.0))


def trial_oracle(t: Trial, control: ControlValues, noise_aware: bool = True) -> str:
    """OFFLOAD, ONLOAD or (noise-aware only) EITHER for a trial (module docstring)."""
    share_off = sum(o.mission_status == COMPLETED for o in t.offload) / len(t.offload)
    share_on = sum(o.mission_status == COMPLETED for o in t.onload) / len(t.onload)
    if share_off != share_on:
        return OFFLOAD if share_off > share_on else ONLOAD
    if share_off == 0:
        return ONLOAD                   # both failed: the safe choice
    v_off, v_on = _completed_values(t.offload, control), _completed_values(t.onload, control)
    m_off, m_on = float(np.mean(v_off)), float(np.mean(v_on))
    if noise_aware:
        sd0 = single_run_sd(control)
        sd_off = float(np.std(v_off, ddof=1)) if len(v_off) > 1 else sd0
        sd_on = float(np.std(v_on, ddof=1)) if len(v_on) > 1 else sd0
        if abs(m_off - m_on) <= 2.0 * math.sqrt(sd_off ** 2 / len(v_off) + sd_on ** 2 / len(v_on)):
            return EITHER
    return OFFLOAD if m_off < m_on else ONLOAD


def regret(t: Trial, choice: str, label: str, control: ControlValues) -> float:
    """The value ``choice`` cost above the oracle's ``label`` in ``t``: 0 when they agree (module docstring)."""
    if agrees(choice, label):
        return 0.0
    runs = {OFFLOAD: (t.offload, t.onload), ONLOAD: (t.onload, t.offload)}
    return max(0.0, placement_value(*runs[choice], control) - placement_value(*runs[label], control))


Policy = Callable[[Trial], str]


def a_priori_rules(settings: DecisionSettings) -> Dict[str, Policy]:
    """The rules fixed before any data, by name (module docstring)."""
    cold = settings.cold_start
    return {ALWAYS_ONLOAD: lambda t: ONLOAD,
            ALWAYS_OFFLOAD: lambda t: OFFLOAD,
            COLD_START_RULE: lambda t: cold.decide(t.c_l, t.r_bw),
            RTT_RULE: lambda t: OFFLOAD if t.c_l < A_PRIORI_RTT else ONLOAD}


def knn_policy(settings: DecisionSettings, rows: Sequence[Row]) -> Policy:
    """The robot's k-NN (no exploration) on ``rows``: its policy on a trial's profile."""
    quiet = DecisionSettings(settings.k, settings.normalisation, settings.cold_start,
                             Exploration(0.0, settings.exploration.max_rtt, 0))
    decider = Decider(quiet, rows)
    return lambda t: decider.policy(t.c_l, t.r_bw).decision


def accuracy(choices: Sequence[str], labels: Sequence[str]) -> float:
    """The share of choices the labels agree with (EITHER: any); NaN without any."""
    return float(np.mean([agrees(c, o) for c, o in zip(choices, labels)])) if labels else math.nan


def change_pct(local: Sequence[float], remote: Sequence[float]) -> float:
    """Remote vs local in % of the local mean (NaN without values)."""
    lo, re = [v for v in local if math.isfinite(v)], [v for v in remote if math.isfinite(v)]
    if not lo or not re or float(np.mean(lo)) == 0:
        return math.nan
    return 100.0 * (float(np.mean(re)) - float(np.mean(lo))) / float(np.mean(lo))


@dataclass(frozen=True)
class Figures:
    """The thesis figures' numbers as the campaign's analysis measured them (NaN: none in the data)."""
    crossing_rbw: float
    crossing_rbw_with_migration: float
    crossing_rtt_ms: float
    move_base_fails_rtt_ms: float
    good_link_time_change_pct: float
    good_link_battery_change_pct: float
    hours: float


@dataclass(frozen=True)
class TaskMeasures:
    task: str
    conditions: int
    training_conditions: int
    held_out: int
    offload_better: int                 # strict oracle, all the task's trials
    offload_beyond_noise: int           # noise-aware oracle
    knn_rows: int
    knn_accuracy: float                 # noise-aware, held-out
    regret_knn: float
    regret_rules: Dict[str, float]
    threshold: Threshold                # the task's own hindsight threshold on its held-out trials

    def as_dict(self) -> Dict:
        best = min(self.regret_rules, key=self.regret_rules.get) if self.regret_rules and \
            all(math.isfinite(v) for v in self.regret_rules.values()) else None
        return dict(conditions=self.conditions, training_conditions=self.training_conditions,
                    held_out=self.held_out, offload_better=self.offload_better,
                    offload_beyond_noise=self.offload_beyond_noise, knn_rows=self.knn_rows,
                    knn_noise_aware_accuracy_40=_num(self.knn_accuracy), regret_knn=_num(self.regret_knn),
                    regret_a_priori={k: _num(v) for k, v in self.regret_rules.items()}, best_a_priori_rule=best,
                    best_threshold=dict(rtt_ms=_num(1000.0 * self.threshold.rtt), r_bw=_num(self.threshold.r_bw),
                                        accuracy=_num(self.threshold.accuracy)))


@dataclass(frozen=True)
class Measures:
    """Everything ``campaign_summary.json`` says, and why a value is missing."""
    summary: Dict                       # SUMMARY_KEYS and per_task
    why_null: Dict[str, str]            # key -> one line


def _num(x: Optional[float]) -> Optional[float]:
    """A finite number, or None (JSON null) for NaN / inf / None."""
    return None if x is None or not math.isfinite(x) else float(x)


def _mean(v: Sequence[float]) -> float:
    return float(np.mean(v)) if len(v) else math.nan


def measures(ts: Sequence[Trial], controls: Mapping[str, ControlValues], training_rows: Sequence[Row],
             settings: DecisionSettings, test_fraction: float, figures: Figures,
             max_rows: int = MAX_ROWS, trained_on: Optional[Sequence[Tuple[str, str]]] = None) -> Measures:
    """The measures of a campaign's trials (module docstring). ``controls``: each task's control values (a task
    without is left out); ``training_rows``: the rows learned during the training conditions, in the order learned
    (each row's ``task`` says whose); ``figures``: the thesis figures' numbers of the analysis; ``trained_on``: the
    training conditions (:func:`training_keys`; default the training trials)."""
    ts = [t for t in ts if t.task in controls]
    train, held = split(ts, test_fraction)
    trained = [k for k in (trained_on if trained_on is not None else [(t.task, t.condition) for t in train])
               if k[0] in controls]
    strict = [trial_oracle(t, controls[t.task], noise_aware=False) for t in ts]
    noise = {(t.task, t.condition): trial_oracle(t, controls[t.task]) for t in ts}
    policies: Dict[str, Policy] = {}            # task -> its k-NN
    knn_rows: Dict[str, int] = {}
    for task in tasks_of(ts):
        rows = [r for r in training_rows if r.task == task][:max_rows]
        policies[task], knn_rows[task] = knn_policy(settings, rows), len(rows)
    rules = a_priori_rules(settings)

    def label(t: Trial) -> str:
        return noise[(t.task, t.condition)]

    def knn(t: Trial) -> str:
        return policies[t.task](t)

    def mean_regret(policy: Policy, of: Sequence[Trial]) -> float:
        return _mean([regret(t, policy(t), label(t), controls[t.task]) for t in of])

    def hindsight(of: Sequence[Trial]) -> Threshold:
        return best_threshold([t.c_l for t in of], [t.r_bw for t in of], [label(t) for t in of])

    per_task = {}
    for task in tasks_of(ts):
        mine, everything = [t for t in held if t.task == task], [t for t in ts if t.task == task]
        per_task[task] = TaskMeasures(
            task=task, conditions=len(everything), training_conditions=sum(k[0] == task for k in trained),
            held_out=len(mine), offload_better=sum(o == OFFLOAD for t, o in zip(ts, strict) if t.task == task),
            offload_beyond_noise=sum(label(t) == OFFLOAD for t in everything), knn_rows=knn_rows[task],
            knn_accuracy=accuracy([knn(t) for t in mine], [label(t) for t in mine]),
            regret_knn=mean_regret(knn, mine),
            regret_rules={name: mean_regret(rule, mine) for name, rule in rules.items()}, threshold=hindsight(mine))
    knn_acc = accuracy([knn(t) for t in held], [label(t) for t in held])
    rule_regret = {name: mean_regret(rule, held) for name, rule in rules.items()}
    best_rule = min(rule_regret, key=rule_regret.get) if held else None
    summary = dict(
        offload_better_share=_num(strict.count(OFFLOAD) / len(ts) if ts else math.nan),
        tasks=tasks_of(ts), training_conditions=len(trained), knn_noise_aware_accuracy_40=_num(knn_acc),
        regret_knn=_num(mean_regret(knn, held)),
        regret_best_a_priori=_num(rule_regret[best_rule]) if best_rule else None, best_a_priori_rule=best_rule,
        knn_minus_best_single_threshold_pts=_num(100.0 * (knn_acc - hindsight(held).accuracy)),
        crossing_rbw=_num(figures.crossing_rbw), crossing_rbw_with_migration=_num(figures.crossing_rbw_with_migration),
        crossing_rtt_ms=_num(figures.crossing_rtt_ms), move_base_fails_rtt_ms=_num(figures.move_base_fails_rtt_ms),
        good_link_time_change_pct=_num(figures.good_link_time_change_pct),
        good_link_battery_change_pct=_num(figures.good_link_battery_change_pct), hours=_num(figures.hours),
        per_task={task: m.as_dict() for task, m in per_task.items()})
    no_held = 'no held-out condition with both placements run'
    reasons = dict(
        offload_better_share='no condition with both placements run',
        knn_noise_aware_accuracy_40=no_held, regret_knn=no_held, regret_best_a_priori=no_held,
        best_a_priori_rule=no_held, knn_minus_best_single_threshold_pts=no_held,
        crossing_rbw='the power fit of the completed offloaded runs\' T_task over R_bw does not reach CT within the '
                     'measured R_bw (Fig. 5-2)',
        crossing_rbw_with_migration='the same fit does not reach CT minus the median placing time within the '
                                    'measured R_bw, or no placing time was measured (Fig. 5-2)',
        crossing_rtt_ms='the linear fit of the completed offloaded runs\' T_task over RTT does not reach CT within '
                        'the measured RTTs (Fig. 5-4)',
        move_base_fails_rtt_ms='no RTT bin (20 ms) from which on most offloaded runs did not complete',
        good_link_time_change_pct='no good-link pair (RTT < 40 ms, ≥ 10 Mbit/s) with both runs completed',
        good_link_battery_change_pct='no good-link pair (RTT < 40 ms, ≥ 10 Mbit/s) with both runs completed',
        hours='no timed rows (wall_start, wall_time)')
    return Measures(summary, {k: reasons.get(k, 'not measured') for k in SUMMARY_KEYS if summary[k] is None})
