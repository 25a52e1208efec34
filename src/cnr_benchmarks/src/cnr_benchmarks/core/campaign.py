"""The continuous experiment of thesis §5 (exp_campaign.sh) and its control experiment (exp_control.sh), without
ROS: drawing link conditions, writing the task_runner's plan, and the analysis of its results.

Conditions. RTT uniform in [rtt_min, rtt_max] ms, rate log-uniform in [rate_min, rate_max] Mbit/s (a rate spans
decades; uniform would put nine in ten draws above 5 Mbit/s), loss uniform in [loss_min, loss_max]; one
``random.Random(seed)``, so a seed gives the same conditions.

Paired runs. Each condition is run twice, onload first, then offload, both decided by the migration_decider on
one profile: the first run brings move_base home, lets the new link fill the monitor's window, profiles it and
records what the robot's policy decides (k-NN, or the cold-start rule while the set is small: its ``policy``,
the *decision* of the condition), then runs onload; the second reuses that profile and runs offload. The pair
gives the *oracle*: the placement with the better Eq. 4-5 value (evaluation.better_placement). Both runs are
evaluated and learned, so both placements get data in every condition (no exploration is needed). Why this
order: a profile taken while move_base runs on the cloud measures its own laser-scan stream on the link, and an
onload run just after a cloud -> robot migration starts with the clone still warming up under the robot's CPU
cap (both seen in the first campaign, whose plans ran the decided placement first and then ``force: other``;
:func:`pairs` reads both kinds of results). Two runs of
the same placement differ too (the control runs' sd), so the analysis also reports a *noise-aware* oracle: a pair
whose two values differ by no more than :func:`noise_tolerance` (what run-to-run noise alone gives, 95 %) is
EITHER, and any decision is right for it; the strict oracle (tolerance 0) always names a winner.

Learning curve. The conditions are split in order: the first ``1 - test_fraction`` are training conditions
(their rows, in the order the robot learned them), the rest are held out. For n = k, k + 5, ... training rows a
:class:`~network_monitor.core.decision.Decider` (the robot's own k-NN, no exploration) trained on the first n
rows predicts each held-out condition from its decided run's profile; accuracy = the share the oracle agrees with.
Beside it the best static threshold rule "offload iff C_l < a and R_bw > b" fitted on the same n rows (the (a, b)
with the most rows whose label it reproduces, over every observed value, and never-offload).
"""
from __future__ import annotations

import math
import random
import statistics
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from network_monitor.core.decision import DecisionSettings, Decider, Exploration
from network_monitor.core.evaluation import (COMPLETED, OFFLOAD, ONLOAD, ControlValues, Outcome, better_placement,
                                             evaluation_value)
from network_monitor.core.training import Row


@dataclass(frozen=True)
class Ranges:
    rtt_min: float          # ms
    rtt_max: float
    rate_min: float         # Mbit/s (> 0)
    rate_max: float
    loss_min: float         # 0..1
    loss_max: float


@dataclass(frozen=True)
class Condition:
    id: str
    rtt_ms: float
    rate: float             # Mbit/s
    loss: float             # 0..1
    task: str = ''          # the task run under it ('' = the plan's)


def draw_conditions(n: int, seed: int, r: Ranges, first: int = 1) -> List[Condition]:
    """``n`` conditions ``c<first>``... (module docstring). The i-th condition depends only on the seed and i."""
    rng = random.Random(seed)
    out = []
    for i in range(1, first + n):
        rtt = rng.uniform(r.rtt_min, r.rtt_max)
        rate = math.exp(rng.uniform(math.log(r.rate_min), math.log(r.rate_max)))
        loss = rng.uniform(r.loss_min, r.loss_max)
        if i >= first:
            out.append(Condition(f'c{i:04d}', round(rtt, 1), round(rate, 2), round(loss, 4)))
    return out


def assign_tasks(conditions: Sequence[Condition], tasks: Sequence[str]) -> List[Condition]:
    """The conditions dealt to the tasks in turn (the first to ``tasks[0]``, the second to ``tasks[1]``, ...), so
    every task meets conditions from the whole ranges and a session alternates its tasks; one task: unchanged."""
    if len(tasks) < 2:
        return list(conditions)
    return [Condition(c.id, c.rtt_ms, c.rate, c.loss, tasks[i % len(tasks)]) for i, c in enumerate(conditions)]


def plan_document(task: str, location: str, settle: float, conditions: Sequence[Condition]) -> Dict:
    """The task_runner's plan: per condition an onload run on a new profile, then an offload run on the same
    profile (module docstring)."""
    runs = []
    for c in conditions:
        link = dict(delay=c.rtt_ms / 2.0, rate=c.rate, loss=c.loss)
        for placement, reuse in ((ONLOAD, False), (OFFLOAD, True)):
            runs.append(dict(id=f'{c.id}-{placement}', condition=c.id, link=link, force=placement, decide=True,
                             learn=True, explore=False, reuse_profile=reuse, **(dict(task=c.task) if c.task else {})))
    return dict(task=task, location=location, settle=settle, runs=runs)


HELD_OUT_PREFIX = 'h'       # a held-out condition's id in a learning plan (h0071): repeated per placement, never learned


def held_out(condition: str) -> bool:
    """Whether a condition id names a held-out condition of a learning plan (:func:`learning_plan_document`)."""
    return condition.startswith(HELD_OUT_PREFIX)


def learning_split(conditions: Sequence[Condition], test_fraction: float) -> List[Condition]:
    """The conditions with the last ``round(n * test_fraction)`` of each task's renamed held-out (``c0071`` ->
    ``h0071``)."""
    held = set()
    for task in dict.fromkeys(c.task for c in conditions):
        mine = [c.id for c in conditions if c.task == task]
        held.update(mine[len(mine) - int(round(len(mine) * test_fraction)):])
    return [Condition(HELD_OUT_PREFIX + c.id[1:], c.rtt_ms, c.rate, c.loss, c.task) if c.id in held else c
            for c in conditions]


def learning_plan_document(task: str, location: str, settle: float, conditions: Sequence[Condition],
                           repeats: int) -> Dict:
    """The learned decision's campaign: a training condition is run once, placed by the robot's policy with
    exploration, and learned (what a robot in service does: one placement per task, the other one never seen); a
    held-out condition (:func:`held_out`) is run ``repeats`` times per placement, onload and offload alternating, on
    the profile of its first run, never learned: the noise-aware oracle's repeats (core.decision_measures). The
    held-out conditions come first in the plan (they do not depend on what was learned), then the training ones in
    their order."""
    if repeats < 1:
        raise ValueError(f'repeats must be >= 1, got {repeats}')
    runs = []
    # the held-out conditions first: never learned, they measure the oracle whatever the robot has learned, so
    # they stand for any learner (a campaign re-run with another one keeps them) and are made first
    for c in sorted(conditions, key=lambda c: not held_out(c.id)):
        link = dict(delay=c.rtt_ms / 2.0, rate=c.rate, loss=c.loss)
        mine = dict(task=c.task) if c.task else {}          # (a condition's task: several tasks in one plan)
        if not held_out(c.id):
            runs.append(dict(id=f'{c.id}-policy', condition=c.id, link=link, force='', decide=True, learn=True,
                             explore=True, reuse_profile=False, **mine))
            continue
        for i in range(1, repeats + 1):
            for placement in (ONLOAD, OFFLOAD):
                runs.append(dict(id=f'{c.id}-{placement}-{i}', condition=c.id, link=link, force=placement,
                                 decide=True, learn=False, explore=False, reuse_profile=bool(runs) and
                                 runs[-1]['condition'] == c.id, **mine))
    return dict(task=task, location=location, settle=settle, runs=runs)


def control_plan(task: str, location: str, settle: float, runs: int) -> Dict:
    """The control experiment: ``runs`` runs with every module on the robot, no decision (thesis Table 4-5)."""
    return dict(task=task, location=location, settle=settle,
                runs=[dict(id=f'control-{i:02d}', condition=f'control-{i:02d}', force='', decide=False, learn=False,
                           explore=False, reuse_profile=False)
                      for i in range(1, runs + 1)])


def local_remote_plan(task: str, location: str, settle: float, runs: int) -> Dict:
    """Thesis Figs. 5-5/5-6: ``runs`` runs per placement on the link as it is (no restriction), alternating
    onload and offload (so a drift of the machine's load during the session falls on both), placed by the
    decider (forced), not learned."""
    plan = []
    for i in range(1, runs + 1):
        for placement in (ONLOAD, OFFLOAD):
            plan.append(dict(id=f'lr-{i:02d}-{placement}', condition=f'lr-{i:02d}', force=placement, decide=True,
                             learn=False, explore=False, reuse_profile=False))
    return dict(task=task, location=location, settle=settle, runs=plan)


@dataclass(frozen=True)
class Spread:
    n: int              # completed runs
    runs: int           # runs
    mean: float
    sd: float           # sample sd (nan below 2)


def spread(rows: Sequence[Dict[str, str]], placement: str, key: str) -> Spread:
    """Mean and sd of ``key`` over the completed runs of one forced placement (local_remote rows)."""
    mine = [r for r in rows if r.get('force') == placement]
    v = [number(r, key) for r in mine if r.get('mission_status') == COMPLETED]
    v = [x for x in v if math.isfinite(x)]
    return Spread(len(v), len(mine), statistics.mean(v) if v else math.nan,
                  statistics.stdev(v) if len(v) > 1 else math.nan)


# ---------------------------------------------------------------- results
def number(row: Mapping[str, str], key: str) -> float:
    """A result row's field as a number (NaN: missing or not a number)."""
    try:
        return float(row.get(key, ''))
    except (TypeError, ValueError):
        return math.nan


@dataclass(frozen=True)
class Pair:
    condition: str
    rtt_ms: float
    rate: float
    loss: float
    c_l: float              # the condition's profile (its first run's)
    r_bw: float
    decided: str            # what the robot decided (the first run's decision, or its policy when forced)
    reason: str             # knn | cold_start | explore | no_profile
    offload: Outcome
    onload: Outcome
    offload_row: Dict[str, str]
    onload_row: Dict[str, str]


def outcome(row: Dict[str, str]) -> Outcome:
    return Outcome(t_task=number(row, 't_task'), b_task=number(row, 'b_task'), mission_status=row['mission_status'])


def pairs(rows: Sequence[Dict[str, str]], k: int = 5) -> List[Pair]:
    """The conditions with both placements finished (and made), in order. The condition's decision is its first run's:
    the decision it ran, or when that run was forced (this campaign's onload-first plans) the policy it
    recorded, made by k-NN once ``k`` rows with a usable profile had been learned, by the cold-start rule
    before."""
    by: Dict[str, List[Dict[str, str]]] = {}
    learned_before: Dict[str, int] = {}
    learned = 0
    for r in rows:
        if r['condition'] not in by:
            by[r['condition']] = []
            learned_before[r['condition']] = learned
        by[r['condition']].append(r)
        if r.get('learned') == '1':
            learned += 1
    out = []
    for c, runs in by.items():
        # a run whose placement was not made (placed 0: a migration rolled back) did not measure its placement
        # (a row without the `placed` field counts as placed)
        placed = {r['decision']: r for r in runs if r['decision'] in (OFFLOAD, ONLOAD) and r.get('placed') != '0'}
        if set(placed) != {OFFLOAD, ONLOAD}:
            continue
        first, off, on = runs[0], placed[OFFLOAD], placed[ONLOAD]
        if first.get('force'):
            decided = first['policy']
            reason = ('no_profile' if not math.isfinite(number(first, 'c_l')) or not math.isfinite(number(first, 'r_bw'))
                      else 'knn' if learned_before[c] >= k else 'cold_start')
        else:
            decided, reason = first['decision'], first['reason']
        out.append(Pair(c, number(first, 'rtt_ms'), number(first, 'rate_mbit'), number(first, 'loss'), number(first, 'c_l'),
                        number(first, 'r_bw'), decided, reason, outcome(off), outcome(on), off, on))
    return out


EITHER = 'either'           # oracle: both placements completed and their values differ by no more than the noise


def elapsed_time(rows: Sequence[Dict[str, str]], resume_gap: float = 120.0) -> float:
    """Wall-clock time [s] the runs took from the first one's start to the last one's end, what happens between
    runs (evaluation, learning, the next link) included; a gap longer than a run plus ``resume_gap`` (a campaign
    stopped and resumed later) counts as that run only. 0 without timed rows."""
    runs = sorted((number(r, 'wall_start'), number(r, 'wall_time')) for r in rows)
    runs = [(s, w) for s, w in runs if math.isfinite(s) and math.isfinite(w)]
    if not runs:
        return 0.0
    total = runs[-1][1]
    for (s0, w0), (s1, _) in zip(runs, runs[1:]):
        total += s1 - s0 if s1 - s0 <= w0 + resume_gap else w0
    return total


def noise_tolerance(control: ControlValues) -> float:
    """How far apart two runs' Eq. 4-5 values can be by run-to-run noise alone (95 %): a value's sd is
    sqrt((sd_T / CT)^2 + (sd_B / CB)^2) / 2 by the control runs, two runs' difference sqrt(2) times that."""
    sd = 0.5 * math.hypot(control.ct_std / control.ct_mean, control.cb_std / control.cb_mean)
    return 2.0 * math.sqrt(2.0) * sd


def oracle(p: Pair, control: ControlValues, tolerance: float = 0.0) -> str:
    """The better placement of a pair (the lower Eq. 4-5 value; evaluation.better_placement), or EITHER when
    both completed and their values differ by ``tolerance`` or less (0: strict, every pair has a winner)."""
    if tolerance > 0 and p.offload.mission_status == COMPLETED == p.onload.mission_status:
        if abs(evaluation_value(p.offload.t_task, p.offload.b_task, control)
               - evaluation_value(p.onload.t_task, p.onload.b_task, control)) <= tolerance:
            return EITHER
    return better_placement(p.offload, p.onload, control)


def agrees(decision: str, oracle_label: str) -> bool:
    """Is ``decision`` right by the oracle (either placement is right for an EITHER pair)?"""
    return oracle_label in (decision, EITHER)


def constant_accuracy(placement: str, oracle_labels: Sequence[str]) -> float:
    """Accuracy of always deciding ``placement`` against the oracle labels. Never offloading is one of the static
    threshold rules (a = 0), so on conditions where it is right for a share x, a learned rule can be at most
    1 - x above that rule: the goal's "11 points above the best static threshold" needs x < 0.89."""
    return sum(1 for o in oracle_labels if agrees(placement, o)) / max(len(oracle_labels), 1)


def strict_ceiling(noise_labels: Sequence[str]) -> float:
    """The accuracy against the strict oracle that a decision right on every pair beyond the noise can expect:
    on a pair within the noise (EITHER by the noise-aware oracle) the strict winner is the sign of the run-to-run
    noise, either placement with chance 1/2, which no decision made before the runs can know. An accuracy
    goal above it cannot be met on these conditions however the decision is learned."""
    n = len(noise_labels)
    return (n - 0.5 * sum(1 for o in noise_labels if o == EITHER)) / n if n else math.nan


@dataclass(frozen=True)
class Threshold:
    rtt: float                  # s: offload only below
    r_bw: float                 # offload only above
    accuracy: float             # the share of the labels it agrees with


def best_threshold(c_l: Sequence[float], r_bw: Sequence[float], labels: Sequence[str]) -> Threshold:
    """The rule "offload iff C_l < a and R_bw > b" (:func:`static_rule`) that agrees with the most ``labels``
    (:func:`agrees`: EITHER with any), over every observed value; never offloading (a = 0, b = inf) first, and of
    equally good rules the first found (a, then b, ascending)."""
    x, y = np.asarray(c_l, dtype=float), np.asarray(r_bw, dtype=float)
    lab = np.asarray(labels, dtype=object)
    want_off, want_on = lab != ONLOAD, lab != OFFLOAD            # where offloading / onloading is right
    best, best_ok = (0.0, math.inf), int(want_on.sum())
    a_values = np.unique(x[np.isfinite(x)]) + 1e-9
    b_values = np.concatenate([[-math.inf], np.unique(y[np.isfinite(y)])])
    for a in a_values:
        below = x < a
        for b in b_values:
            ok = int(np.sum(np.where(below & (y > b), want_off, want_on)))
            if ok > best_ok:
                best, best_ok = (float(a), float(b)), ok
    return Threshold(best[0], best[1], best_ok / len(lab) if len(lab) else math.nan)


def static_rule_fit(rows: Sequence[Row]) -> Tuple[float, float]:
    """The best rule "offload iff C_l < a and R_bw > b" on the rows' labels: (a, b); (0, inf) = never offload."""
    t = best_threshold([r.c_l for r in rows], [r.r_bw for r in rows], [r.label for r in rows])
    return t.rtt, t.r_bw


def static_rule(a: float, b: float, c_l: float, r_bw: float) -> str:
    return OFFLOAD if c_l < a and r_bw > b else ONLOAD


def paired_rows(pairs: Sequence[Pair], labels: Sequence[str]) -> List[Row]:
    """One training row per pair at its profile, labelled with the pair's oracle (``labels``, strict): what a
    robot that ran both placements under the link learns from comparing them, instead of judging each run alone
    against the control values (the thesis's V_r rule, which labels a good offload run offload and a good onload
    run onload under the same link). Pairs without a usable profile are left out."""
    out = []
    for p, label in zip(pairs, labels):
        if not (math.isfinite(p.c_l) and math.isfinite(p.r_bw)):
            continue
        run = p.offload if label == OFFLOAD else p.onload
        out.append(Row(r_bw=p.r_bw, c_l=p.c_l, decision=label, mission_status=run.mission_status,
                       b_task=run.b_task, t_task=run.t_task, timestamp=0.0, task='', location='',
                       placement='', rtt_spread=math.nan, loss=math.nan, profile_method='', value=math.nan,
                       good=True, label=label, explored=False, source='paired'))
    return out


def learning_curve(rows: Sequence[Row], train_conditions: int, held_out: Sequence[Pair], oracle_labels: Sequence[str],
                   settings: DecisionSettings, step: int = 5) -> List[Dict]:
    """Accuracy on the held-out pairs of the k-NN and of the best static rule trained on the first n rows, for
    n = k, k + step, ..., all the rows (module docstring). ``rows`` are the training set's rows of the training
    conditions, in order."""
    settings = DecisionSettings(settings.k, settings.normalisation, settings.cold_start,
                                Exploration(0.0, settings.exploration.max_rtt, 0))
    sizes = list(range(settings.k, len(rows) + 1, step))
    if rows and (not sizes or sizes[-1] != len(rows)):
        sizes.append(len(rows))
    out = []
    for n in sizes:
        knn = Decider(settings, rows[:n])
        a, b = static_rule_fit(rows[:n])
        k_ok = sum(1 for p, o in zip(held_out, oracle_labels) if agrees(knn.policy(p.c_l, p.r_bw).decision, o))
        s_ok = sum(1 for p, o in zip(held_out, oracle_labels) if agrees(static_rule(a, b, p.c_l, p.r_bw), o))
        m = max(len(held_out), 1)
        out.append(dict(rows=n, knn=k_ok / m, static=s_ok / m, rule_rtt=a, rule_r_bw=b, held_out=len(held_out),
                        train_conditions=train_conditions))
    return out


def power_fit(x: Sequence[float], y: Sequence[float]) -> Optional[Tuple[float, float]]:
    """y = a x^b by least squares in log-log (positive values only); None with fewer than 3 points."""
    pts = [(math.log(u), math.log(v)) for u, v in zip(x, y) if u > 0 and v > 0 and math.isfinite(u + v)]
    fit = linear_fit([p[0] for p in pts], [p[1] for p in pts])
    return None if fit is None else (math.exp(fit[0]), fit[1])


def crossing(fit: Tuple[float, float], level: float, lo: float = 0.0, hi: float = math.inf) -> float:
    """x where a x^b = level, if it lies in [lo, hi] (the measured range: no extrapolation); else NaN."""
    a, b = fit
    if b == 0 or a <= 0 or level <= 0:
        return math.nan
    x = (level / a) ** (1.0 / b)
    return x if lo <= x <= hi else math.nan


def linear_fit(x: Sequence[float], y: Sequence[float]) -> Optional[Tuple[float, float]]:
    """y = a + b x by least squares; None with fewer than 3 points."""
    pts = [(a, b) for a, b in zip(x, y) if math.isfinite(a + b)]
    if len(pts) < 3:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx == 0:
        return None
    b = sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx
    return my - b * mx, b


def failure_rtt(points: Sequence[Tuple[float, str]], width: float = 20.0) -> float:
    """The lowest RTT bin (ms, its lower edge) from which on most offloaded runs did not complete; NaN if none."""
    bins: Dict[int, List[bool]] = {}
    for rtt, status in points:
        if math.isfinite(rtt):
            bins.setdefault(int(rtt // width), []).append(status == COMPLETED)
    for i in sorted(bins):
        if all(sum(bins[j]) * 2 < len(bins[j]) for j in sorted(bins) if j >= i):
            return i * width
    return math.nan
