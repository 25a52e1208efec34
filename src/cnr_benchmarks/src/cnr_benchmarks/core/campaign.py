"""The continuous experiment of thesis §5 (exp_campaign.sh) and its control experiment (exp_control.sh), without
ROS: drawing link conditions, writing the task_runner's plan, and the analysis of its results.

Conditions. RTT uniform in [rtt_min, rtt_max] ms, rate log-uniform in [rate_min, rate_max] Mbit/s (a rate spans
decades; uniform would put nine in ten draws above 5 Mbit/s), loss uniform in [loss_min, loss_max]; one
``random.Random(seed)``, so a seed gives the same conditions.

Paired runs. Each condition is run twice: first as the migration_decider decides (the robot's own decision, as
in the thesis), then with the other placement (``force: other``). The pair gives the *oracle*: the placement
with the better Eq. 4-5 value (evaluation.better_placement). Both runs are evaluated and learned. Two runs of
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
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

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


def plan_document(task: str, location: str, settle: float, conditions: Sequence[Condition]) -> Dict:
    """The task_runner's plan: per condition the decided run, then the other placement (module docstring)."""
    runs = []
    for c in conditions:
        link = dict(delay=c.rtt_ms / 2.0, rate=c.rate, loss=c.loss)
        runs.append(dict(id=f'{c.id}-decided', condition=c.id, link=link, force='', decide=True, learn=True,
                         explore=True))
        runs.append(dict(id=f'{c.id}-other', condition=c.id, link=link, force='other', decide=True, learn=True,
                         explore=False))
    return dict(task=task, location=location, settle=settle, runs=runs)


def control_plan(task: str, location: str, settle: float, runs: int) -> Dict:
    """The control experiment: ``runs`` runs with every module on the robot, no decision (thesis Table 4-5)."""
    return dict(task=task, location=location, settle=settle,
                runs=[dict(id=f'control-{i:02d}', condition=f'control-{i:02d}', force='', decide=False, learn=False,
                           explore=False)
                      for i in range(1, runs + 1)])


# ---------------------------------------------------------------- results
def _f(row: Dict[str, str], key: str) -> float:
    try:
        return float(row.get(key, ''))
    except ValueError:
        return math.nan


@dataclass(frozen=True)
class Pair:
    condition: str
    rtt_ms: float
    rate: float
    loss: float
    c_l: float              # the decided run's profile
    r_bw: float
    decided: str            # what the robot decided
    reason: str
    offload: Outcome
    onload: Outcome
    offload_row: Dict[str, str]
    onload_row: Dict[str, str]


def outcome(row: Dict[str, str]) -> Outcome:
    return Outcome(t_task=_f(row, 't_task'), b_task=_f(row, 'b_task'), mission_status=row['mission_status'])


def pairs(rows: Sequence[Dict[str, str]]) -> List[Pair]:
    """The conditions with both runs finished, in order."""
    by: Dict[str, Dict[str, Dict[str, str]]] = {}
    order: List[str] = []
    for r in rows:
        if r['condition'] not in by:
            order.append(r['condition'])
        by.setdefault(r['condition'], {})[r['id'].rsplit('-', 1)[-1]] = r
    out = []
    for c in order:
        d, o = by[c].get('decided'), by[c].get('other')
        if d is None or o is None or {d['decision'], o['decision']} != {OFFLOAD, ONLOAD}:
            continue
        off, on = (d, o) if d['decision'] == OFFLOAD else (o, d)
        out.append(Pair(c, _f(d, 'rtt_ms'), _f(d, 'rate_mbit'), _f(d, 'loss'), _f(d, 'c_l'), _f(d, 'r_bw'),
                        d['decision'], d['reason'], outcome(off), outcome(on), off, on))
    return out


EITHER = 'either'           # oracle: both placements completed and their values differ by no more than the noise


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


def static_rule_fit(rows: Sequence[Row]) -> Tuple[float, float]:
    """The best rule "offload iff C_l < a and R_bw > b" on the rows' labels: (a, b); (0, inf) = never offload."""
    best, best_ok = (0.0, math.inf), sum(1 for r in rows if r.label == ONLOAD)
    rtts = sorted({r.c_l for r in rows})
    rbws = sorted({r.r_bw for r in rows})
    a_values = [x + 1e-9 for x in rtts]
    b_values = [-math.inf] + [x for x in rbws]
    for a in a_values:
        for b in b_values:
            ok = sum(1 for r in rows if (r.c_l < a and r.r_bw > b) == (r.label == OFFLOAD))
            if ok > best_ok:
                best, best_ok = (a, b), ok
    return best


def static_rule(a: float, b: float, c_l: float, r_bw: float) -> str:
    return OFFLOAD if c_l < a and r_bw > b else ONLOAD


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
