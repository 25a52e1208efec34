"""The campaign's analysis: oracle accuracy, learning curve and Figures 5-1 to 5-6 beside the thesis's numbers
(``campaign analyse``; cnr_benchmarks.core.campaign has the computations), one function per figure and table.
Writes into ``--out``: learning_curve.tsv, learning_curve_paired.tsv, fig5_1_decision_map.png ... fig5_6_time.png,
campaign_summary.json (the learned decision's measures: cnr_benchmarks.core.decision_measures) and the page
README.md; and the local-vs-remote page (``local_remote``)."""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cnr_benchmarks import report, results  # noqa: E402
from cnr_benchmarks.core import campaign as core  # noqa: E402
from cnr_benchmarks.core import decision_measures as dm  # noqa: E402
from cnr_benchmarks.session import slowdown_dir  # noqa: E402

COMMAND_FILE = 'command.txt'        # in the campaign's folder: the command that made its rows
TRAINING_FILE = 'training_set.tsv'  # in the campaign's page folder: the robot's learned set, published
SUMMARY_FILE = 'campaign_summary.json'


def _fmt(x: float, digits: int = 1) -> str:
    return '–' if not math.isfinite(x) else f'{x:.{digits}f}'


def _command(args: argparse.Namespace) -> str:
    """The command that made the rows (``<out>/command.txt``, written by the campaign) and, if it differs, the one
    that analysed them."""
    this = _this_command(args)
    made = _made_command(args)
    return f'`{made}`' + ('' if made == this else f' (analysed by `{this}`)')


def _this_command(args: argparse.Namespace) -> str:
    return f'launch_scripts/exp_campaign.sh {" ".join(args.argv)}'


def _made_command(args: argparse.Namespace) -> str:
    path = os.path.join(args.out, COMMAND_FILE)
    return open(path).read().strip() if os.path.exists(path) else _this_command(args)


def _shown(path: str) -> str:
    """``path`` relative to the workspace when it lies inside it."""
    return os.path.relpath(path, report.WS) if path.startswith(report.WS + os.sep) else path


LEARNING_CURVE_KEYS = ('rows', 'knn', 'static', 'knn_noise', 'static_noise', 'rule_rtt', 'rule_r_bw', 'held_out',
                       'train_conditions')
FIGURE_SIZE = (6.4, 4.8)


@dataclass
class Analysis:
    """A campaign's rows read and paired, judged by the oracles, with the learning curves of its training rows."""
    args: argparse.Namespace
    rows: List[Dict[str, str]]          # the rows analysed: the first task's (--exclude left out)
    all_rows: List[Dict[str, str]]      # every row
    task_rows: List[Dict[str, str]]     # the rows analysed of every task (the decision's measures)
    excluded: List[str]
    decision: Any                       # config/decision.yaml's decision section
    control: Any                        # the control values (CT, CB)
    learned: List[Any]                  # the training rows the robot learned itself
    training_warnings: List[str]
    pairs: List[Any]
    oracle: List[str]                   # strict: every pair has a winner
    oracle_noise: List[str]             # noise-aware: EITHER within the noise
    tolerance: float
    n_train: int                        # training pairs (a learning plan's training conditions are mostly not)
    n_test: int
    trained_on: int                     # conditions the robot learned from (a learning plan's: every one not held out)
    curve: List[Dict]                   # learning curve of the rows learned during the training conditions
    curve_p: List[Dict]                 # the same with one row per training pair, labelled by its oracle

    @property
    def offload_rows(self) -> List[Dict[str, str]]:
        from network_monitor.core.evaluation import OFFLOAD
        return [r for r in self.rows if r['decision'] == OFFLOAD]

    @property
    def onload_rows(self) -> List[Dict[str, str]]:
        from network_monitor.core.evaluation import ONLOAD
        return [r for r in self.rows if r['decision'] == ONLOAD]

    @property
    def done_off(self) -> List[Dict[str, str]]:
        """The offloaded runs that completed."""
        from cnr_mission.core.task import COMPLETED
        return [r for r in self.offload_rows if r['mission_status'] == COMPLETED]


def load_analysis(args: argparse.Namespace) -> Union[Analysis, int]:
    """The campaign's analysis, or the exit status after a one-line problem (2: bad --exclude or control values,
    1: no rows)."""
    from cnr_mission.core.task import read_results
    from cnr_params import ConfigError
    from network_monitor.core.decision_config import load_decision_config
    from network_monitor.core.evaluation import load_control_values
    rows_path = os.path.join(args.out, 'results.tsv')
    rows, warnings = read_results(rows_path)
    for w in warnings:
        print(w, file=sys.stderr)
    excluded = sorted({c for c in args.exclude.split(',') if c})
    unknown = [c for c in excluded if c not in {r['condition'] for r in rows}]
    if unknown:
        print(f'campaign analyse: --exclude: no such condition in {rows_path}: {", ".join(unknown)}', file=sys.stderr)
        return 2
    all_rows, task_rows = rows, [r for r in rows if r['condition'] not in excluded]
    rows = [r for r in task_rows if (r['task'] or args.task) == args.task]
    if not rows:
        print(f'campaign analyse: no results in {rows_path}', file=sys.stderr)
        return 1
    cfg = load_decision_config(os.path.join(report.WS, 'config', 'decision.yaml'))
    try:
        control = load_control_values(args.control_values, args.task)
    except ConfigError as exc:
        print(f'campaign analyse: {exc}', file=sys.stderr)
        return 2
    training, tw = read_training(args, args.task)
    pairs = core.pairs(rows, cfg.decision.k)
    if any(core.held_out(p.condition) for p in pairs):
        # a learning plan: its held-out conditions are held out; the robot learned from every other condition (run
        # once each, so mostly not pairs)
        pairs = [p for p in pairs if not core.held_out(p.condition)] + [p for p in pairs if core.held_out(p.condition)]
        n_test = sum(core.held_out(p.condition) for p in pairs)
        trained_on = set(dm.training_keys(rows, dm.trials(rows, args.task), args.test_fraction, args.task))
    else:
        n_test = int(round(len(pairs) * args.test_fraction))
        trained_on = {(args.task, p.condition) for p in pairs[:len(pairs) - n_test]}
    n_train = len(pairs) - n_test
    oracle = [core.oracle(p, control) for p in pairs]
    tolerance = core.noise_tolerance(control)
    oracle_noise = [core.oracle(p, control, tolerance) for p in pairs]
    learned = [t for t in training if t.source == 'local']
    train_rows = dm.learned_during(learned, rows, trained_on, args.task)
    curve = _learning_curve(train_rows, n_train, pairs, oracle, oracle_noise, cfg.decision, len(trained_on))
    # the same with one row per training pair labelled by the pair's (strict) oracle (core.paired_rows)
    paired = core.paired_rows(pairs[:n_train], oracle[:n_train])
    curve_p = _learning_curve(paired, n_train, pairs, oracle, oracle_noise, cfg.decision, n_train)
    return Analysis(args, rows, all_rows, task_rows, excluded, cfg.decision, control, learned, tw, pairs, oracle, oracle_noise,
                    tolerance, n_train, n_test, len(trained_on), curve, curve_p)


def published_training(args: argparse.Namespace, task: str) -> str:
    """Where a task's training set is published beside the rows: ``<out>/training_set.tsv`` for the campaign's
    first task, ``<out>/training_set_<task>.tsv`` for another."""
    name = TRAINING_FILE if task == args.task else TRAINING_FILE.replace('.tsv', f'_{task}.tsv')
    return os.path.join(args.out, name)


def read_training(args: argparse.Namespace, task: str) -> Tuple[List[Any], List[str]]:
    """The robot's training set of ⟨task, --location⟩ in the scratch (``<scratch>/training``), or without it the one
    published beside the rows (:func:`published_training`): rows and warnings."""
    from network_monitor.core.training import TrainingSet, read_rows
    path = TrainingSet(os.path.join(args.scratch, 'training'), task, args.location).path
    if not os.path.exists(path) and os.path.exists(published_training(args, task)):
        path = published_training(args, task)
    return read_rows(path)


def _learning_curve(train_rows: Sequence, n_train: int, pairs: Sequence, oracle: Sequence[str],
                    oracle_noise: Sequence[str], decision, train_conditions: int) -> List[Dict]:
    """k-NN and the best static threshold on the held-out pairs (those after the first ``n_train``) as the training
    rows grow, against both oracles."""
    curve = core.learning_curve(train_rows, train_conditions, pairs[n_train:], oracle[n_train:], decision)
    curve_noise = core.learning_curve(train_rows, train_conditions, pairs[n_train:], oracle_noise[n_train:], decision)
    for c, cn in zip(curve, curve_noise):
        c.update(knn_noise=cn['knn'], static_noise=cn['static'])
    return curve


def learning_curve_table(curve: Sequence[Dict]) -> Tuple[Sequence[str], List[List[str]]]:
    """A learning curve as TSV columns and rows."""
    return LEARNING_CURVE_KEYS, [[str(c[k]) for k in LEARNING_CURVE_KEYS] for c in curve]


def _finish(fig, ax, xlabel: str, ylabel: str, title: str, title_size: Optional[float] = None,
            legend_loc: Optional[str] = None):
    """Label a figure's axes, title and legend (small) and lay it out; returns the figure."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, **({'fontsize': title_size} if title_size else {}))
    ax.legend(fontsize=8, **({'loc': legend_loc} if legend_loc else {}))
    fig.tight_layout()
    return fig


def fig_decision_map(a: Analysis):
    """Fig. 5-1: the k-NN decision map over (RTT, R_bw) with the learned rows."""
    from network_monitor.core.decision import Decider, DecisionSettings, Exploration
    from network_monitor.core.evaluation import OFFLOAD, ONLOAD
    s = a.decision
    final = Decider(DecisionSettings(s.k, s.normalisation, s.cold_start, Exploration(0.0, s.exploration.max_rtt, 0)),
                    a.learned)
    rtt_axis = np.linspace(0.0, max([0.25] + [1.05 * t.c_l for t in a.learned]), 120)
    rbw_axis = np.logspace(-0.5, 3.0, 120)
    grid = np.array([[1.0 if final.policy(x, y).decision == OFFLOAD else 0.0 for x in rtt_axis] for y in rbw_axis])
    fig, ax = plt.subplots(figsize=FIGURE_SIZE)
    ax.pcolormesh(rtt_axis * 1000, rbw_axis, grid, cmap='coolwarm_r', alpha=0.25, shading='auto', vmin=0, vmax=1)
    for label, colour in ((OFFLOAD, 'tab:blue'), (ONLOAD, 'tab:red')):
        pts = [(t.c_l * 1000, t.r_bw) for t in a.learned if t.label == label]
        if pts:
            ax.scatter(*zip(*pts), s=14, c=colour, label=f'label {label}')
    ax.set_yscale('log')
    return _finish(fig, ax, 'C_l: RTT before the task [ms]', 'R_bw = A_bw / C_bw',
                   f'Fig. 5-1: k-NN (k = {s.k}) decision map, {len(a.learned)} rows\n'
                   '(shaded blue: offload, red: onload)',
                   legend_loc='lower left')


@dataclass
class Crossings:
    """Where offloading matches CT: in R_bw (Fig. 5-2; also with the measured migration time) and in RTT (Fig. 5-4),
    and the RTT from which remote move_base fails."""
    r_bw: float
    r_bw_with_migration: float
    migration_time: float
    rtt: float
    fail_rtt: float


def fig_time_vs_rbw(a: Analysis) -> Tuple[Any, float, float, float]:
    """Fig. 5-2: T_task vs R_bw (offloaded, completed), power fit, crossing with CT; (figure, crossing, crossing with
    the measured migration time, that time)."""
    ct = a.control.ct_mean
    x = [core.number(r, 'r_bw') for r in a.done_off]
    y = [core.number(r, 't_task') for r in a.done_off]
    placing = [core.number(r, 'placing_time') for r in a.offload_rows if core.number(r, 'placing_time') > 0]
    migration_time = statistics.median(placing) if placing else math.nan
    fit = core.power_fit(x, y)
    x_lo, x_hi = (min(x), max(x)) if x else (0.0, 0.0)
    cross = core.crossing(fit, ct, x_lo, x_hi) if fit else math.nan
    cross_mig = core.crossing(fit, ct - migration_time, x_lo, x_hi) \
        if fit and math.isfinite(migration_time) else math.nan
    fig, ax = plt.subplots(figsize=FIGURE_SIZE)
    ax.scatter(x, y, s=14, label='offloaded runs (completed)')
    ax.axhline(ct, color='k', ls='--', label=f'CT = {ct:.1f} s (all local)')
    if fit:
        xs = np.logspace(math.log10(max(min(x), 1e-3)), math.log10(max(x)), 100)
        ax.plot(xs, fit[0] * xs ** fit[1], 'tab:orange', label=f'T = {fit[0]:.1f} R_bw^{fit[1]:.3f}')
    ax.set_xscale('log')
    _finish(fig, ax, 'R_bw', 'T_task [s]', f'Fig. 5-2: task time vs R_bw (crossing with CT: {_fmt(cross, 2)}; '
            f'with the measured migration {_fmt(migration_time)} s: {_fmt(cross_mig, 2)})', title_size=8)
    return fig, cross, cross_mig, migration_time


def fig_operating_time(a: Analysis):
    """Fig. 5-3: operating time (a full battery's worth of such tasks) vs R_bw."""
    def op_hours(r: Dict[str, str]) -> float:
        b = core.number(r, 'b_task')
        return core.number(r, 't_task') / b / 3600.0 if b > 0 else math.nan
    fig, ax = plt.subplots(figsize=FIGURE_SIZE)
    ax.scatter([core.number(r, 'r_bw') for r in a.done_off], [op_hours(r) for r in a.done_off], s=14, label='offloaded')
    local_op = a.control.ct_mean / a.control.cb_mean / 3600.0
    ax.axhline(local_op, color='k', ls='--', label=f'all local: {local_op:.2f} h')
    ax.set_xscale('log')
    return _finish(fig, ax, 'R_bw', 'operating time on a full battery [h] (T_task / B_task)',
                   'Fig. 5-3: operating time vs R_bw')


def fig_time_vs_rtt(a: Analysis) -> Tuple[Any, float, float]:
    """Fig. 5-4: T_task vs RTT (offloaded), linear fit, crossing with CT; (figure, crossing, failure RTT)."""
    from cnr_mission.core.task import COMPLETED
    ct = a.control.ct_mean
    xr = [core.number(r, 'c_l') * 1000 for r in a.done_off]
    y = [core.number(r, 't_task') for r in a.done_off]
    lin = core.linear_fit(xr, y)
    cross_rtt = (ct - lin[0]) / lin[1] if lin and lin[1] > 0 else math.nan
    if not (xr and min(xr) <= cross_rtt <= max(xr)):
        cross_rtt = math.nan            # not within the measured RTTs: no extrapolation
    fail_rtt = core.failure_rtt([(core.number(r, 'rtt_ms'), r['mission_status']) for r in a.offload_rows])
    failed = [r for r in a.offload_rows if r['mission_status'] != COMPLETED]
    fig, ax = plt.subplots(figsize=FIGURE_SIZE)
    ax.scatter(xr, y, s=14, label='offloaded, completed')
    if failed:
        ax.scatter([core.number(r, 'c_l') * 1000 for r in failed], [core.number(r, 't_task') for r in failed], s=18, marker='x',
                   c='tab:red', label='offloaded, not completed')
    ax.axhline(ct, color='k', ls='--', label=f'CT = {ct:.1f} s')
    if lin:
        xs = np.linspace(0, max(xr + [1.0]), 50)
        ax.plot(xs, lin[0] + lin[1] * xs, 'tab:orange', label=f'T = {lin[0]:.1f} + {lin[1]:.3f} RTT')
    _finish(fig, ax, 'C_l: RTT [ms]', 'T_task [s]', f'Fig. 5-4: task time vs RTT (crossing with CT {_fmt(cross_rtt)} '
            f'ms; remote move_base fails from {_fmt(fail_rtt, 0)} ms)', title_size=8)
    return fig, cross_rtt, fail_rtt


def good_link_pairs(a: Analysis) -> List[Any]:
    """The pairs on good links (RTT < 40 ms, >= 10 Mbit/s) whose runs both completed (Figs. 5-5, 5-6)."""
    from cnr_mission.core.task import COMPLETED
    return [p for p in a.pairs if p.rtt_ms < 40 and p.rate >= 10 and p.offload.mission_status == COMPLETED
            and p.onload.mission_status == COMPLETED]


def figs_local_vs_remote(good: Sequence[Any]) -> Dict[str, Any]:
    """Figs. 5-5 and 5-6: battery and time, local vs remote, per good-link pair."""
    figures = {}
    for name, key, unit, title in (('fig5_5_battery.png', 'b_task', 'battery used [fraction]',
                                    'Fig. 5-5: battery, local vs remote move_base'),
                                   ('fig5_6_time.png', 't_task', 'T_task [s]',
                                    'Fig. 5-6: task time, local vs remote move_base')):
        loc = [getattr(p.onload, key) for p in good]
        rem = [getattr(p.offload, key) for p in good]
        fig, ax = plt.subplots(figsize=FIGURE_SIZE)
        if loc:
            ax.plot(range(1, len(loc) + 1), loc, 'o-', label='local (onload)')
            ax.plot(range(1, len(rem) + 1), rem, 's-', label='remote (offload)')
        figures[name] = _finish(fig, ax, 'paired condition (RTT < 40 ms, rate >= 10 Mbit/s)', unit, title)
    return figures


def _finite(v: Sequence[float]) -> List[float]:
    return [a for a in v if math.isfinite(a)]


def _mean(v: Sequence[float]) -> float:
    v = _finite(v)
    return statistics.mean(v) if v else math.nan


def _median(v: Sequence[float]) -> float:
    v = _finite(v)
    return statistics.median(v) if v else math.nan


def summary_text(a: Analysis) -> str:
    """The paragraphs ahead of the tables: the command and the runs, the time budget, the runs by status and the
    oracles."""
    from network_monitor.core.evaluation import OFFLOAD
    rows, pairs = a.rows, a.pairs
    wall = sum(core.number(r, 'wall_time') for r in rows if math.isfinite(core.number(r, 'wall_time')))
    learning = any(core.held_out(p.condition) for p in pairs)
    # a learning plan's training conditions run once each: only a held-out one lacks a pair
    unpaired = sorted({r['condition'] for r in rows if core.held_out(r['condition']) or not learning}
                      - {p.condition for p in pairs})
    not_placed = sorted({r['id'] for r in rows if r.get('placed') == '0'})
    statuses: Dict[Tuple[str, str], int] = {}
    for r in rows:
        statuses[(r['decision'], r['mission_status'])] = statuses.get((r['decision'], r['mission_status']), 0) + 1
    either = sum(1 for o in a.oracle_noise if o == core.EITHER)
    tasks = getattr(a.args, 'tasks', [a.args.task])
    several = (f'Tasks {", ".join(tasks)}, the conditions dealt to them in turn, each learned per ⟨task, location⟩: '
               f'this paragraph, the accuracy table, the thesis\'s figures and Figures 5-1 to 5-6 are {a.args.task}\'s '
               f'runs, the summary below every task\'s.\n' if len(tasks) > 1 else '')
    return several + '\n'.join([
        f'{_command(a.args)}: {len(rows)} runs, '
        + (f'{a.trained_on} training conditions run once each in the placement the robot chose, {a.n_test} held-out '
           f'conditions with both placements repeated' if learning else
           f'{len(pairs)} paired conditions ({a.n_train} training, {a.n_test} held out)')
        + f', {wall / 3600:.2f} h of runs; control values: CT '
        f'{a.control.ct_mean:.2f} s, CB {a.control.cb_mean:.6f} ({a.control.runs} runs, {a.control.date}).'
        + (f' Left out (--exclude): {", ".join(a.excluded)}.' if a.excluded else '')
        + (f' Without a pair: {", ".join(unpaired)}' + (f' (a placement not made: {", ".join(not_placed)})'
                                                        if not_placed else '') + '.' if unpaired else '') + '\n',
        time_budget(a),
        'Runs by placement and status: ' + ', '.join(f'{d} {s}: {n}' for (d, s), n in sorted(statuses.items()))
        + '\n',
        f'Oracle: strict = the pair\'s lower Eq. 4-5 value wins; noise-aware = a pair whose two values differ by '
        f'≤ {a.tolerance:.3f} (two runs\' 95 % spread by the control runs\' sd) is "either" and any decision is right '
        f'for it: {either} of {len(pairs)} pairs. Offload was the better placement in '
        f'{sum(1 for o in a.oracle if o == OFFLOAD)} of {len(pairs)} pairs strictly, in '
        f'{sum(1 for o in a.oracle_noise if o == OFFLOAD)} beyond the noise.\n'])


def time_budget(a: Analysis) -> str:
    """Where a paired condition's wall-clock time goes (runs with a decision: the task, placing, the rest), and the
    elapsed time of the whole campaign."""
    pair_wall = _median([core.number(p.offload_row, 'wall_time') + core.number(p.onload_row, 'wall_time') for p in a.pairs])

    def med_of(rs: Sequence[Dict[str, str]], key: str) -> str:
        return _fmt(_median([core.number(r, key) for r in rs]))
    on, off = a.onload_rows, a.offload_rows
    budget = (f'Per paired condition (median over {len(a.pairs)}): {_fmt(pair_wall)} s of wall-clock time, i.e. 100 '
              f'conditions in {_fmt(100 * pair_wall / 3600, 2)} h; onload run {med_of(on, "wall_time")} s '
              f'(task {med_of(on, "t_task")} s), offload run {med_of(off, "wall_time")} s (task '
              f'{med_of(off, "t_task")} s, placing {med_of(off, "placing_time")} s).')
    decided = [r for r in a.all_rows if r.get('t_decision')]
    budget += (f' A decided run\'s task time and battery count its placement; the whole decision (profile and '
               f'placing, either placement pays the profile) took a median {med_of(decided, "t_decision")} s and '
               f'{_fmt(_median([core.number(r, "b_decision") for r in decided]), 6)} of the battery.' if decided
               else ' The task times are the drives alone (these runs did not record the placement\'s cost in '
               f'them).')
    elapsed = core.elapsed_time(a.all_rows)               # every condition run, left out or not
    n_run = len({r['condition'] for r in a.all_rows})
    if n_run and elapsed > 0:
        budget += (f" Elapsed from the first run's start to the last one's end, the evaluation and learning between "
                   f'runs included (the pause of a stopped and resumed campaign left out): {_fmt(elapsed / 3600, 2)} h '
                   f'for {n_run} conditions, {_fmt(elapsed / n_run)} s each, i.e. 100 in '
                   f'{_fmt(100 * elapsed / n_run / 3600, 2)} h.')
    return budget + '\n'


def _at_most_40(curve: Sequence[Dict]) -> Optional[Dict]:
    within = [c for c in curve if c['rows'] <= 40]
    return within[-1] if within else None


def accuracy_table(a: Analysis) -> List[str]:
    """The decisions against both oracles: online, k-NN and the best static threshold on the held-out conditions."""
    from network_monitor.core.evaluation import OFFLOAD, ONLOAD
    pairs, n_train, n_test = a.pairs, a.n_train, a.n_test

    def agreeing(labels: Sequence[str], lo: int = 0) -> int:
        return sum(1 for p, o in zip(pairs[lo:], labels[lo:]) if core.agrees(p.decided, o))

    def pct(k: int, n: int) -> str:
        return f'{k}/{n} ({_fmt(100 * k / max(n, 1), 0)} %)'

    def const(labels: Sequence[str]) -> str:
        return ' / '.join(f'{_fmt(100 * core.constant_accuracy(d, labels), 0)} %' for d in (ONLOAD, OFFLOAD))

    def acc(c: Optional[Dict], key: str) -> str:
        return f'{_fmt(100 * c[key], 0)} %' if c else '–'
    last, at40 = (a.curve[-1] if a.curve else None), _at_most_40(a.curve)
    last_p, at40_p = (a.curve_p[-1] if a.curve_p else None), _at_most_40(a.curve_p)
    oracle, oracle_noise = a.oracle, a.oracle_noise
    return [
        '| measure | thesis | measured: strict oracle | noise-aware oracle |', '|---|---|---|---|',
        f'| decisions the oracle agrees with, all conditions (online, as learned) | – | '
        f'{pct(agreeing(oracle), len(pairs))} | {pct(agreeing(oracle_noise), len(pairs))} |',
        f'| same, held-out conditions only | – | {pct(agreeing(oracle, n_train), n_test)} | '
        f'{pct(agreeing(oracle_noise, n_train), n_test)} |',
        f'| k-NN accuracy on held-out, all {last["rows"] if last else 0} training rows | Eom et al. 87.5 % | '
        f'{acc(last, "knn")} | {acc(last, "knn_noise")} |',
        f'| k-NN accuracy with ≤ 40 rows ({at40["rows"] if at40 else 0} rows) | goal ≥ 90 % | {acc(at40, "knn")} | '
        f'{acc(at40, "knn_noise")} |',
        f'| best static threshold, same rows (RTT < {_fmt(1000 * last["rule_rtt"], 0) if last else "–"} ms, '
        f'R_bw > {_fmt(last["rule_r_bw"], 2) if last else "–"}) | MALMOS: k-NN +10.9–40.5 points | '
        f'{acc(last, "static")} | {acc(last, "static_noise")} |',
        f'| the most any decision can expect against the strict labels of the held-out conditions: right beyond '
        f'the noise, a coin flip on the {sum(1 for o in oracle_noise[n_train:] if o == core.EITHER)} of {n_test} '
        f'within it (`strict_ceiling`) | goal ≥ 90 % | {_fmt(100 * core.strict_ceiling(oracle_noise[n_train:]), 0)} % '
        f'| 100 % |',
        f'| the majority placement alone on the held-out conditions (never offload / always offload): a learned '
        f'rule can be at most 100 % minus the larger above a static rule | goal: +11 points needs < 89 % | '
        f'{const(oracle[n_train:])} | {const(oracle_noise[n_train:])} |',
        f'| paired labels (one row per training pair, labelled by its oracle: `learning_curve_paired.tsv`): k-NN, '
        f'all {last_p["rows"] if last_p else 0} rows | – | {acc(last_p, "knn")} | {acc(last_p, "knn_noise")} |',
        f'| same, ≤ 40 rows ({at40_p["rows"] if at40_p else 0} rows) | goal ≥ 90 % | {acc(at40_p, "knn")} | '
        f'{acc(at40_p, "knn_noise")} |',
        f'| best static threshold on the paired rows (RTT < '
        f'{_fmt(1000 * last_p["rule_rtt"], 0) if last_p else "–"} ms, R_bw > '
        f'{_fmt(last_p["rule_r_bw"], 2) if last_p else "–"}) | – | {acc(last_p, "static")} | '
        f'{acc(last_p, "static_noise")} |']


def thesis_table(a: Analysis, crossings: Crossings, good: Sequence[Any]) -> List[str]:
    """The figures' numbers beside the thesis's: crossings with CT, the failure RTT, local vs remote."""
    ct, cb = a.control.ct_mean, a.control.cb_mean
    y = [core.number(r, 't_task') for r in a.done_off]
    b_local, b_remote = [p.onload.b_task for p in good], [p.offload.b_task for p in good]
    t_local, t_remote = [p.onload.t_task for p in good], [p.offload.t_task for p in good]
    db = 100.0 * (_mean(b_remote) - _mean(b_local)) / _mean(b_local) if b_local else math.nan
    dt = _mean(t_remote) - _mean(t_local) if t_local else math.nan
    return [
        '| measure | thesis | measured |', '|---|---|---|',
        f'| offloaded runs faster than CT / cheaper than CB | (thesis: above R_bw ≈ 4.9 / most runs) | '
        f'{sum(1 for v in y if v < ct)} of {len(y)} / '
        f'{sum(1 for r in a.done_off if core.number(r, "b_task") < cb)} of {len(a.done_off)} |',
        f'| Fig. 5-2: R_bw where offloading matches CT (– : no crossing within the measured R_bw) | ≈ 4.9 | '
        f'{_fmt(crossings.r_bw, 2)} |',
        f'| same, with the measured migration time ({_fmt(crossings.migration_time)} s, median placing time) | '
        f'≈ 10 (5 s) | {_fmt(crossings.r_bw_with_migration, 2)} |',
        f'| Fig. 5-4: RTT where offloading matches CT (– : none within the measured RTTs) | ≈ 55 ms | '
        f'{_fmt(crossings.rtt)} ms |',
        f'| RTT from which remote move_base fails | ≈ 160 ms | {_fmt(crossings.fail_rtt, 0)} ms |',
        f'| Fig. 5-5: battery, remote vs local (good links, {len(good)} pairs) | −10 % | {_fmt(db)} % |',
        f'| Fig. 5-6: task time, remote − local | −2.4 s | {_fmt(dt)} s |']


# campaign_summary.json's keys beside the thesis's figures and the goals (key -> (thesis / goal, unit))
SUMMARY_BESIDE = {
    'offload_better_share': ('goal 25–75 % of the conditions', '%'),
    'tasks': ('goal ≥ 2 tasks whose boundaries differ', ''),
    'training_conditions': ('goal ≥ 100 over all tasks', ''),
    'knn_noise_aware_accuracy_40': ('goal ≥ 90 % with ≤ 40 rows per task; Eom et al. 87.5 %', '%'),
    'regret_knn': ('goal ≤ 1/3 of the best a-priori rule\'s', ''),
    'regret_best_a_priori': ('–', ''),
    'best_a_priori_rule': ('always onload, always offload, the cold-start rule, offload iff RTT < 50 ms', ''),
    'knn_minus_best_single_threshold_pts': ('goal ≥ 11 points (MALMOS +10.9–40.5)', ' points'),
    'crossing_rbw': ('≈ 4.9 (Fig. 5-2)', ''),
    'crossing_rbw_with_migration': ('≈ 10 (Fig. 5-2, 5 s migration)', ''),
    'crossing_rtt_ms': ('≈ 55 ms (Fig. 5-4)', ' ms'),
    'move_base_fails_rtt_ms': ('≈ 160 ms', ' ms'),
    'good_link_time_change_pct': ('−2.7 % (−2.4 s of 88 s, Fig. 5-6)', ' %'),
    'good_link_battery_change_pct': ('−10 % (Fig. 5-5)', ' %'),
    'hours': ('budget ≤ 4 h', ' h')}


def decision_measures(a: Analysis, crossings: Crossings, good: Sequence[Any]) -> dm.Measures:
    """The learned decision's measures (cnr_benchmarks.core.decision_measures) of the analysis: every task of the
    rows with control values, the robot's rows of the training conditions, the figures' numbers."""
    from cnr_params import ConfigError
    from network_monitor.core.evaluation import load_control_values
    ts = dm.trials(a.task_rows, a.args.task)
    controls = {a.args.task: a.control}
    learned = list(a.learned)
    for task in dm.tasks_of(ts):
        if task not in controls:
            try:
                controls[task] = load_control_values(a.args.control_values, task)
            except ConfigError as exc:
                print(f'campaign analyse: {exc}: its conditions left out of {SUMMARY_FILE}', file=sys.stderr)
                continue
            learned += [t for t in read_training(a.args, task)[0] if t.source == 'local']
    trained_on = dm.training_keys(a.task_rows, ts, a.args.test_fraction, a.args.task)
    train_rows = dm.learned_during(learned, a.task_rows, set(trained_on), a.args.task)
    elapsed = core.elapsed_time(a.all_rows)
    figures = dm.Figures(crossings.r_bw, crossings.r_bw_with_migration, crossings.rtt, crossings.fail_rtt,
                         dm.change_pct([p.onload.t_task for p in good], [p.offload.t_task for p in good]),
                         dm.change_pct([p.onload.b_task for p in good], [p.offload.b_task for p in good]),
                         elapsed / 3600.0 if elapsed > 0 else math.nan)
    return dm.measures(ts, controls, train_rows, a.decision, a.args.test_fraction, figures, trained_on=trained_on)


def summary_table(m: dm.Measures) -> List[str]:
    """campaign_summary.json as a table beside the thesis's figures and the goals (a missing value with its
    reason), and its ``per_task`` as a table."""
    def shown(key: str) -> str:
        v, unit = m.summary[key], SUMMARY_BESIDE[key][1]
        if v is None:
            return f'– ({m.why_null[key]})'
        if isinstance(v, list):
            return f'{len(v)}: {", ".join(v)}'
        if isinstance(v, (str, int)):
            return str(v)
        return f'{100 * v:.1f} %' if unit == '%' else f'{v:.3g}{unit}'

    def num(v: Optional[float], scale: float = 1.0, digits: int = 3) -> str:
        return '–' if v is None else _fmt(scale * v, digits)

    def threshold(t: Dict) -> str:
        th = t['best_threshold']
        return (f'RTT < {num(th["rtt_ms"], digits=0)} ms' + ('' if th['r_bw'] is None else f', R_bw > '
                                                            f'{num(th["r_bw"], digits=2)}')
                + f': {num(th["accuracy"], 100, 0)} %')
    per_task = [f'| {task} | {t["conditions"]} ({t["training_conditions"]} / {t["held_out"]}) | '
                f'{t["offload_better"]} / {t["offload_beyond_noise"]} | '
                f'{num(t["knn_noise_aware_accuracy_40"], 100, 0)} % ({t["knn_rows"]} rows) | '
                f'{num(t["regret_knn"])} | {t["best_a_priori_rule"] or "–"} '
                f'({num(t["regret_a_priori"].get(t["best_a_priori_rule"]))}) | {threshold(t)} |'
                for task, t in m.summary['per_task'].items()]
    return [f'Summary (`{SUMMARY_FILE}`; held-out conditions; the noise-aware oracle from the repeats or, with one '
            f'run per placement, the control runs\' spread; regret: Eq. 4-5 value above the oracle\'s, a run that '
            f'did not complete counted as the task redone in the other placement plus one control task; '
            f'cnr_benchmarks.core.decision_measures):', '',
            '| key | thesis / goal | measured |', '|---|---|---|',
            *[f'| `{k}` | {SUMMARY_BESIDE[k][0]} | {shown(k)} |' for k in SUMMARY_BESIDE], '',
            '| task (`per_task`) | conditions (training / held out) | offload better: strict / beyond the noise | '
            'k-NN, noise-aware | regret k-NN | best a-priori rule (regret) | its own hindsight threshold |',
            '|---|---|---|---|---|---|---|', *per_task]


def curve_text(title: str, curve: Sequence[Dict]) -> str:
    return f'{title}: ' + ', '.join(
        f'{c["rows"]} rows: k-NN {100 * c["knn"]:.0f} % / static {100 * c["static"]:.0f} % (noise-aware '
        f'{100 * c["knn_noise"]:.0f} % / {100 * c["static_noise"]:.0f} %)' for c in curve)


def write_analysis(args: argparse.Namespace) -> int:
    """The page README.md, the learning curves (TSV) and Figures 5-1 to 5-6 in ``args.out``."""
    a = load_analysis(args)
    if isinstance(a, int):
        return a
    figures = {'fig5_1_decision_map.png': fig_decision_map(a)}
    figures['fig5_2_time_vs_rbw.png'], cross, cross_mig, migration_time = fig_time_vs_rbw(a)
    figures['fig5_3_operating_time.png'] = fig_operating_time(a)
    figures['fig5_4_time_vs_rtt.png'], cross_rtt, fail_rtt = fig_time_vs_rtt(a)
    good = good_link_pairs(a)
    figures.update(figs_local_vs_remote(good))
    crossings = Crossings(cross, cross_mig, migration_time, cross_rtt, fail_rtt)
    measures = decision_measures(a, crossings, good)
    results.save_json(os.path.join(args.out, SUMMARY_FILE), measures.summary)
    lines = [summary_text(a), *accuracy_table(a), '', *thesis_table(a, crossings, good), '',
             *summary_table(measures), '',
             curve_text('Learning curve (learning_curve.tsv)', a.curve), '',
             curve_text('Learning curve, paired labels (learning_curve_paired.tsv)', a.curve_p), '',
             'Figures: fig5_1_decision_map.png, fig5_2_time_vs_rbw.png, fig5_3_operating_time.png, '
             'fig5_4_time_vs_rtt.png, fig5_5_battery.png, fig5_6_time.png.']
    if a.training_warnings:
        lines.append('\nTraining set warnings: ' + '; '.join(a.training_warnings))
    slowdown = getattr(args, 'slowdown', None)
    title = 'Continuous experiment ' + (f'at 1/{slowdown:g} robot CPU' if slowdown is not None
                                        else 'at the default robot CPU cap')
    text = results.write_page(args.out, title, 'thesis §5, Figs. 5-1 to 5-6', '\n'.join(lines) + '\n',
                              _made_command(args), figures,
                              {'learning_curve.tsv': learning_curve_table(a.curve),
                               'learning_curve_paired.tsv': learning_curve_table(a.curve_p)})
    print(text, flush=True)
    return 0


# ---------------------------------------------------------------- local vs remote (thesis Figs. 5-5, 5-6)
THESIS_LR_BATTERY_PCT = -10.0       # remote vs local battery per task (thesis §5.1 on Figs. 5-5/5-6)
THESIS_LR_TIME_S = -2.4             # remote - local task time (2.8 %)


def write_local_remote(args: argparse.Namespace) -> int:
    """The page README.md, fig5_5_battery.png and fig5_6_time.png in ``args.out`` from the rows of each slowdown
    (``<out>/slowdown_<s>/results.tsv``): mean and sd per placement of the completed runs, as the thesis's
    Figs. 5-5/5-6 (bars with different local CPU frequency)."""
    from cnr_mission.core.task import read_results
    from network_monitor.core.evaluation import OFFLOAD, ONLOAD
    table, bars = [], []
    for s in args.slowdowns:
        path = os.path.join(slowdown_dir(args.out, s), 'results.tsv')
        rows, warnings = read_results(path) if os.path.exists(path) else ([], [])
        for w in warnings:
            print(w, file=sys.stderr)
        if not rows:
            print(f'exp_local_remote: no results for slowdown {s:g} ({path})', file=sys.stderr)
            continue
        t = {p: core.spread(rows, p, 't_task') for p in (ONLOAD, OFFLOAD)}
        b = {p: core.spread(rows, p, 'b_task') for p in (ONLOAD, OFFLOAD)}
        dt = t[OFFLOAD].mean - t[ONLOAD].mean
        db = 100.0 * (b[OFFLOAD].mean - b[ONLOAD].mean) / b[ONLOAD].mean if b[ONLOAD].mean else math.nan
        bars.append((s, t, b))
        table.append([f'{s:g} ({1 / s:.3g} CPU)',
                      f'{t[ONLOAD].n}/{t[ONLOAD].runs}', f'{t[OFFLOAD].n}/{t[OFFLOAD].runs}',
                      f'{_fmt(t[ONLOAD].mean)} ({_fmt(t[ONLOAD].sd)})', f'{_fmt(t[OFFLOAD].mean)} ({_fmt(t[OFFLOAD].sd)})',
                      f'{_fmt(dt)} s ({_fmt(100 * dt / t[ONLOAD].mean)} %)',
                      f'{_fmt(b[ONLOAD].mean, 5)} ({_fmt(b[ONLOAD].sd, 5)})', f'{_fmt(b[OFFLOAD].mean, 5)} ({_fmt(b[OFFLOAD].sd, 5)})',
                      f'{_fmt(db)} %'])
    if not bars:
        return 1
    figures = {}
    for name, key, unit, title in (('fig5_5_battery.png', 2, 'battery used per task [fraction]',
                                    'Fig. 5-5: battery per task, local vs remote'),
                                   ('fig5_6_time.png', 1, 'T_task [s]', 'Fig. 5-6: task time, local vs remote')):
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        x = np.arange(len(bars))
        for j, (p, label) in enumerate(((ONLOAD, 'local (onload)'), (OFFLOAD, 'remote (offload)'))):
            ax.bar(x + (j - 0.5) * 0.38, [bar[key][p].mean for bar in bars], 0.38,
                   yerr=[bar[key][p].sd if math.isfinite(bar[key][p].sd) else 0.0 for bar in bars],
                   capsize=4, label=label)
            for i, bar in enumerate(bars):          # no completed run: say so where its bar would be
                if not math.isfinite(bar[key][p].mean):
                    ax.text(x[i] + (j - 0.5) * 0.38, 0.0, f' {p}: {bar[key][p].n} of {bar[key][p].runs} completed',
                            rotation=90, ha='center', va='bottom', fontsize=8)
        ax.set_xticks(x)
        ax.set_xticklabels([f'slowdown {bar[0]:g}\n({1 / bar[0]:.3g} CPU)' for bar in bars])
        ax.set_ylabel(unit)
        ax.set_title(title + ' (mean, sd)')
        ax.legend(fontsize=8)
        fig.tight_layout()
        figures[name] = fig
    md = (f'{len(bars)} slowdown(s) with rows in `slowdown_<s>/results.tsv` (their plans and sessions in '
          f'`{_shown(args.scratch)}/slowdown_<s>/`): {args.task}@{args.location}, the link '
          f'unrestricted, runs alternating local (every module on the robot) and remote (move_base migrated to '
          f'the cloud before the task), at each robot CPU slowdown (the robot\'s cgroup capped at 1/slowdown '
          f'CPU; the thesis compared local CPU frequencies). Mean (sd) of the completed runs.\n\n'
          + report.markdown_table(['robot slowdown (cap)', 'local done', 'remote done', 'T local [s]',
                                   'T remote [s]', 'remote − local T', 'B local', 'B remote',
                                   'remote vs local B'], table)
          + f'\n\nThesis (20 runs each, unrestricted network, 1.6 GHz): remote {THESIS_LR_BATTERY_PCT:g} % battery, '
          f'{THESIS_LR_TIME_S:g} s (−2.8 %) task time.\n\nFigures: fig5_5_battery.png, fig5_6_time.png.\n')
    print(results.write_page(args.out, 'Local vs remote move_base on an unrestricted link', 'thesis Figs. 5-5, 5-6',
                             md, f'launch_scripts/exp_local_remote.sh {" ".join(args.argv)}', figures), flush=True)
    return 0
