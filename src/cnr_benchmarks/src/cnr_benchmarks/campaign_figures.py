"""The campaign's analysis: oracle accuracy, learning curve and Figures 5-1 to 5-6 beside the thesis's numbers
(``campaign analyse``; cnr_benchmarks.core.campaign has the computations). Writes into ``--out``:
learning_curve.tsv, fig5_1_decision_map.png ... fig5_6_time.png and campaign.md."""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
from typing import Dict, Optional, Sequence

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cnr_benchmarks import report  # noqa: E402
from cnr_benchmarks.core import campaign as core  # noqa: E402


def _num(row: Dict[str, str], key: str) -> float:
    try:
        return float(row[key])
    except (KeyError, ValueError):
        return math.nan


def _fmt(x: float, digits: int = 1) -> str:
    return '–' if not math.isfinite(x) else f'{x:.{digits}f}'


def _command(args: argparse.Namespace) -> str:
    """The command that made the rows (``<out>/command.txt``, written by the campaign) and, if it differs, the one
    that analysed them."""
    this = f'launch_scripts/exp_campaign.sh {" ".join(args.argv)}'
    path = os.path.join(args.out, 'command.txt')
    made = open(path).read().strip() if os.path.exists(path) else this
    return f'`{made}`' + ('' if made == this else f' (analysed by `{this}`)')


def write_analysis(args: argparse.Namespace) -> int:
    from cnr_mission.core.task import COMPLETED, read_results
    from cnr_params import ConfigError
    from network_monitor.core.decision_config import load_decision_config
    from network_monitor.core.evaluation import OFFLOAD, ONLOAD, load_control_values
    from network_monitor.core.training import TrainingSet
    results = os.path.join(args.out, 'results.tsv')
    rows, warnings = read_results(results)
    for w in warnings:
        print(w, file=sys.stderr)
    excluded = sorted({c for c in args.exclude.split(',') if c})
    unknown = [c for c in excluded if c not in {r['condition'] for r in rows}]
    if unknown:
        print(f'campaign analyse: --exclude: no such condition in {results}: {", ".join(unknown)}', file=sys.stderr)
        return 2
    all_rows, rows = rows, [r for r in rows if r['condition'] not in excluded]
    if not rows:
        print(f'campaign analyse: no results in {results}', file=sys.stderr)
        return 1
    cfg = load_decision_config(os.path.join(report.WS, 'config', 'decision.yaml'))
    try:
        control = load_control_values(args.control_values, args.task)
    except ConfigError as exc:
        print(f'campaign analyse: {exc}', file=sys.stderr)
        return 2
    training, tw = TrainingSet(os.path.join(args.out, 'training'), args.task, args.location).read()
    pairs = core.pairs(rows, cfg.decision.k)
    oracle = [core.oracle(p, control) for p in pairs]                      # strict: every pair has a winner
    tolerance = core.noise_tolerance(control)
    oracle_noise = [core.oracle(p, control, tolerance) for p in pairs]    # noise-aware: EITHER within the noise
    either = sum(1 for o in oracle_noise if o == core.EITHER)
    n_test = int(round(len(pairs) * args.test_fraction))
    n_train = len(pairs) - n_test
    train_ids = {p.condition for p in pairs[:n_train]}
    # the rows learned during the training conditions: each row's timestamp falls in its run's wall-clock span
    spans = [(_num(r, 'wall_start'), _num(r, 'wall_start') + _num(r, 'wall_time'), r['condition']) for r in rows]

    def condition_of(t: float) -> str:
        return next((c for a, b, c in spans if a <= t <= b + 1.0), '')
    learned = [t for t in training if t.source == 'local']
    train_rows = [t for t in learned if condition_of(t.timestamp) in train_ids]
    curve = core.learning_curve(train_rows, n_train, pairs[n_train:], oracle[n_train:], cfg.decision)
    curve_noise = core.learning_curve(train_rows, n_train, pairs[n_train:], oracle_noise[n_train:], cfg.decision)
    for c, cn in zip(curve, curve_noise):
        c.update(knn_noise=cn['knn'], static_noise=cn['static'])
    with open(os.path.join(args.out, 'learning_curve.tsv'), 'w') as f:
        keys = ('rows', 'knn', 'static', 'knn_noise', 'static_noise', 'rule_rtt', 'rule_r_bw', 'held_out',
                'train_conditions')
        f.write('\t'.join(keys) + '\n')
        for c in curve:
            f.write('\t'.join(str(c[k]) for k in keys) + '\n')

    # the same with one row per training pair labelled by the pair's (strict) oracle (core.paired_rows)
    prs = core.paired_rows(pairs[:n_train], oracle[:n_train])
    curve_p = core.learning_curve(prs, n_train, pairs[n_train:], oracle[n_train:], cfg.decision)
    curve_pn = core.learning_curve(prs, n_train, pairs[n_train:], oracle_noise[n_train:], cfg.decision)
    for c, cn in zip(curve_p, curve_pn):
        c.update(knn_noise=cn['knn'], static_noise=cn['static'])
    with open(os.path.join(args.out, 'learning_curve_paired.tsv'), 'w') as f:
        f.write('\t'.join(keys) + '\n')
        for c in curve_p:
            f.write('\t'.join(str(c[k]) for k in keys) + '\n')

    def agreeing(labels: Sequence[str], lo: int = 0) -> int:
        return sum(1 for p, o in zip(pairs[lo:], labels[lo:]) if core.agrees(p.decided, o))
    online, online_late = agreeing(oracle), agreeing(oracle, n_train)
    online_n, online_late_n = agreeing(oracle_noise), agreeing(oracle_noise, n_train)
    offload_rows = [r for r in rows if r['decision'] == OFFLOAD]
    onload_rows = [r for r in rows if r['decision'] == ONLOAD]

    # ---- Fig. 5-1: the k-NN decision map over (RTT, R_bw) with the rows
    from network_monitor.core.decision import Decider, DecisionSettings, Exploration
    s = cfg.decision
    final = Decider(DecisionSettings(s.k, s.normalisation, s.cold_start, Exploration(0.0, s.exploration.max_rtt, 0)),
                    learned)
    rtt_axis = np.linspace(0.0, max([0.25] + [1.05 * t.c_l for t in learned]), 120)
    rbw_axis = np.logspace(-0.5, 3.0, 120)
    grid = np.array([[1.0 if final.policy(x, y).decision == OFFLOAD else 0.0 for x in rtt_axis] for y in rbw_axis])
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.pcolormesh(rtt_axis * 1000, rbw_axis, grid, cmap='coolwarm_r', alpha=0.25, shading='auto', vmin=0, vmax=1)
    for label, colour in ((OFFLOAD, 'tab:blue'), (ONLOAD, 'tab:red')):
        pts = [(t.c_l * 1000, t.r_bw) for t in learned if t.label == label]
        if pts:
            ax.scatter(*zip(*pts), s=14, c=colour, label=f'label {label}')
    ax.set_yscale('log')
    ax.set_xlabel('C_l: RTT before the task [ms]')
    ax.set_ylabel('R_bw = A_bw / C_bw')
    ax.set_title(f'Fig. 5-1: k-NN (k = {s.k}) decision map, {len(learned)} rows\n'
                 '(shaded blue: offload, red: onload)')
    ax.legend(loc='lower left', fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'fig5_1_decision_map.png'), dpi=110)
    plt.close(fig)

    # ---- Fig. 5-2: T_task vs R_bw (offloaded, completed), power fit, crossing with CT
    done_off = [r for r in offload_rows if r['mission_status'] == COMPLETED]
    x = [_num(r, 'r_bw') for r in done_off]
    y = [_num(r, 't_task') for r in done_off]
    placing = [_num(r, 'placing_time') for r in offload_rows if _num(r, 'placing_time') > 0]
    migration_time = statistics.median(placing) if placing else math.nan
    fit = core.power_fit(x, y)
    x_lo, x_hi = (min(x), max(x)) if x else (0.0, 0.0)
    cross = core.crossing(fit, control.ct_mean, x_lo, x_hi) if fit else math.nan
    cross_mig = core.crossing(fit, control.ct_mean - migration_time, x_lo, x_hi) \
        if fit and math.isfinite(migration_time) else math.nan
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.scatter(x, y, s=14, label='offloaded runs (completed)')
    ax.axhline(control.ct_mean, color='k', ls='--', label=f'CT = {control.ct_mean:.1f} s (all local)')
    if fit:
        xs = np.logspace(math.log10(max(min(x), 1e-3)), math.log10(max(x)), 100)
        ax.plot(xs, fit[0] * xs ** fit[1], 'tab:orange', label=f'T = {fit[0]:.1f} R_bw^{fit[1]:.3f}')
    ax.set_xscale('log')
    ax.set_xlabel('R_bw')
    ax.set_ylabel('T_task [s]')
    ax.set_title(f'Fig. 5-2: task time vs R_bw (crossing with CT: {_fmt(cross, 2)}; '
                 f'with the measured migration {_fmt(migration_time)} s: {_fmt(cross_mig, 2)})', fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'fig5_2_time_vs_rbw.png'), dpi=110)
    plt.close(fig)

    # ---- Fig. 5-3: operating time (a full battery's worth of such tasks) vs R_bw
    def op_hours(r: Dict[str, str]) -> float:
        b = _num(r, 'b_task')
        return _num(r, 't_task') / b / 3600.0 if b > 0 else math.nan
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.scatter([_num(r, 'r_bw') for r in done_off], [op_hours(r) for r in done_off], s=14, label='offloaded')
    local_op = control.ct_mean / control.cb_mean / 3600.0
    ax.axhline(local_op, color='k', ls='--', label=f'all local: {local_op:.2f} h')
    ax.set_xscale('log')
    ax.set_xlabel('R_bw')
    ax.set_ylabel('operating time on a full battery [h] (T_task / B_task)')
    ax.set_title('Fig. 5-3: operating time vs R_bw')
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'fig5_3_operating_time.png'), dpi=110)
    plt.close(fig)

    # ---- Fig. 5-4: T_task vs RTT (offloaded), linear fit, crossing with CT; failure RTT
    xr = [_num(r, 'c_l') * 1000 for r in done_off]
    lin = core.linear_fit(xr, y)
    cross_rtt = (control.ct_mean - lin[0]) / lin[1] if lin and lin[1] > 0 else math.nan
    if not (xr and min(xr) <= cross_rtt <= max(xr)):
        cross_rtt = math.nan            # not within the measured RTTs: no extrapolation
    fail_rtt = core.failure_rtt([(_num(r, 'rtt_ms'), r['mission_status']) for r in offload_rows])
    failed = [r for r in offload_rows if r['mission_status'] != COMPLETED]
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.scatter(xr, y, s=14, label='offloaded, completed')
    if failed:
        ax.scatter([_num(r, 'c_l') * 1000 for r in failed], [_num(r, 't_task') for r in failed], s=18, marker='x',
                   c='tab:red', label='offloaded, not completed')
    ax.axhline(control.ct_mean, color='k', ls='--', label=f'CT = {control.ct_mean:.1f} s')
    if lin:
        xs = np.linspace(0, max(xr + [1.0]), 50)
        ax.plot(xs, lin[0] + lin[1] * xs, 'tab:orange', label=f'T = {lin[0]:.1f} + {lin[1]:.3f} RTT')
    ax.set_xlabel('C_l: RTT [ms]')
    ax.set_ylabel('T_task [s]')
    ax.set_title(f'Fig. 5-4: task time vs RTT (crossing with CT {_fmt(cross_rtt)} ms; remote move_base fails '
                 f'from {_fmt(fail_rtt, 0)} ms)', fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, 'fig5_4_time_vs_rtt.png'), dpi=110)
    plt.close(fig)

    # ---- Fig. 5-5 / 5-6: battery and time, local vs remote, under good links (RTT < 40 ms, >= 10 Mbit/s)
    good = [p for p in pairs if p.rtt_ms < 40 and p.rate >= 10 and p.offload.mission_status == COMPLETED
            and p.onload.mission_status == COMPLETED]
    b_local = [p.onload.b_task for p in good]
    b_remote = [p.offload.b_task for p in good]
    t_local = [p.onload.t_task for p in good]
    t_remote = [p.offload.t_task for p in good]
    for name, loc, rem, unit, title in (('fig5_5_battery.png', b_local, b_remote, 'battery used [fraction]',
                                         'Fig. 5-5: battery, local vs remote move_base'),
                                        ('fig5_6_time.png', t_local, t_remote, 'T_task [s]',
                                         'Fig. 5-6: task time, local vs remote move_base')):
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        if loc:
            ax.plot(range(1, len(loc) + 1), loc, 'o-', label='local (onload)')
            ax.plot(range(1, len(rem) + 1), rem, 's-', label='remote (offload)')
        ax.set_xlabel('paired condition (RTT < 40 ms, rate >= 10 Mbit/s)')
        ax.set_ylabel(unit)
        ax.set_title(title)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, name), dpi=110)
        plt.close(fig)

    def mean(v: Sequence[float]) -> float:
        v = [a for a in v if math.isfinite(a)]
        return statistics.mean(v) if v else math.nan
    db = 100.0 * (mean(b_remote) - mean(b_local)) / mean(b_local) if b_local else math.nan
    dt = mean(t_remote) - mean(t_local) if t_local else math.nan

    # ---- campaign.md
    last = curve[-1] if curve else None
    within = [c for c in curve if c['rows'] <= 40]
    at40 = within[-1] if within else None
    last_p = curve_p[-1] if curve_p else None
    within_p = [c for c in curve_p if c['rows'] <= 40]
    at40_p = within_p[-1] if within_p else None
    statuses = {}
    for r in rows:
        statuses[(r['decision'], r['mission_status'])] = statuses.get((r['decision'], r['mission_status']), 0) + 1
    wall = sum(_num(r, 'wall_time') for r in rows if math.isfinite(_num(r, 'wall_time')))
    # where a paired condition's wall-clock time goes (runs with a decision: the task, placing, the rest)
    def med(v: Sequence[float]) -> float:
        v = [a for a in v if math.isfinite(a)]
        return statistics.median(v) if v else math.nan
    pair_wall = med([_num(p.offload_row, 'wall_time') + _num(p.onload_row, 'wall_time') for p in pairs])
    def med_of(rs: Sequence[Dict[str, str]], key: str) -> str:
        return _fmt(med([_num(r, key) for r in rs]))
    budget = (f'Per paired condition (median over {len(pairs)}): {_fmt(pair_wall)} s of wall-clock time, i.e. 100 '
              f'conditions in {_fmt(100 * pair_wall / 3600, 2)} h; onload run {med_of(onload_rows, "wall_time")} s '
              f'(task {med_of(onload_rows, "t_task")} s), offload run {med_of(offload_rows, "wall_time")} s (task '
              f'{med_of(offload_rows, "t_task")} s, placing {med_of(offload_rows, "placing_time")} s).')
    elapsed = core.elapsed_time(all_rows)                 # every condition run, left out or not
    n_run = len({r['condition'] for r in all_rows})
    if n_run and elapsed > 0:
        budget += (f" Elapsed from the first run's start to the last one's end, the evaluation and learning between "
                   f'runs included (the pause of a stopped and resumed campaign left out): {_fmt(elapsed / 3600, 2)} h '
                   f'for {n_run} conditions, {_fmt(elapsed / n_run)} s each, i.e. 100 in '
                   f'{_fmt(100 * elapsed / n_run / 3600, 2)} h.')
    budget += '\n'
    def pct(k: int, n: int) -> str:
        return f'{k}/{n} ({_fmt(100 * k / max(n, 1), 0)} %)'

    def const(labels: Sequence[str]) -> str:
        return ' / '.join(f'{_fmt(100 * core.constant_accuracy(d, labels), 0)} %' for d in (ONLOAD, OFFLOAD))

    def acc(c: Optional[Dict], key: str) -> str:
        return f'{_fmt(100 * c[key], 0)} %' if c else '–'
    paired_ids = {p.condition for p in pairs}
    unpaired = sorted({r['condition'] for r in rows} - paired_ids)
    not_placed = sorted({r['id'] for r in rows if r.get('placed') == '0'})
    lines = [
        f'# Continuous experiment (thesis §5)\n',
        f'{_command(args)}: {len(rows)} runs, {len(pairs)} paired conditions '
        f'({n_train} training, {n_test} held out), {wall / 3600:.2f} h of runs; control values: CT '
        f'{control.ct_mean:.2f} s, CB {control.cb_mean:.6f} ({control.runs} runs, {control.date}).'
        + (f' Left out (--exclude): {", ".join(excluded)}.' if excluded else '')
        + (f' Without a pair: {", ".join(unpaired)}' + (f' (a placement not made: {", ".join(not_placed)})'
                                                        if not_placed else '') + '.' if unpaired else '') + '\n',
        budget,
        'Runs by placement and status: ' + ', '.join(f'{d} {s}: {n}' for (d, s), n in sorted(statuses.items()))
        + '\n',
        f'Oracle: strict = the pair\'s lower Eq. 4-5 value wins; noise-aware = a pair whose two values differ by '
        f'≤ {tolerance:.3f} (two runs\' 95 % spread by the control runs\' sd) is "either" and any decision is right '
        f'for it: {either} of {len(pairs)} pairs. Offload was the better placement in '
        f'{sum(1 for o in oracle if o == OFFLOAD)} of {len(pairs)} pairs strictly, in '
        f'{sum(1 for o in oracle_noise if o == OFFLOAD)} beyond the noise.\n',
        '| measure | thesis | measured: strict oracle | noise-aware oracle |', '|---|---|---|---|',
        f'| decisions the oracle agrees with, all conditions (online, as learned) | – | {pct(online, len(pairs))} | '
        f'{pct(online_n, len(pairs))} |',
        f'| same, held-out conditions only | – | {pct(online_late, n_test)} | {pct(online_late_n, n_test)} |',
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
        f'{acc(last_p, "static_noise")} |',
        '', '| measure | thesis | measured |', '|---|---|---|',
        f'| offloaded runs faster than CT / cheaper than CB | (thesis: above R_bw ≈ 4.9 / most runs) | '
        f'{sum(1 for v in y if v < control.ct_mean)} of {len(y)} / '
        f'{sum(1 for r in done_off if _num(r, "b_task") < control.cb_mean)} of {len(done_off)} |',
        f'| Fig. 5-2: R_bw where offloading matches CT (– : no crossing within the measured R_bw) | ≈ 4.9 | '
        f'{_fmt(cross, 2)} |',
        f'| same, with the measured migration time ({_fmt(migration_time)} s, median placing time) | ≈ 10 (5 s) | '
        f'{_fmt(cross_mig, 2)} |',
        f'| Fig. 5-4: RTT where offloading matches CT (– : none within the measured RTTs) | ≈ 55 ms | '
        f'{_fmt(cross_rtt)} ms |',
        f'| RTT from which remote move_base fails | ≈ 160 ms | {_fmt(fail_rtt, 0)} ms |',
        f'| Fig. 5-5: battery, remote vs local (good links, {len(good)} pairs) | −10 % | {_fmt(db)} % |',
        f'| Fig. 5-6: task time, remote − local | −2.4 s | {_fmt(dt)} s |',
        '',
        'Learning curve (learning_curve.tsv): ' + ', '.join(
            f'{c["rows"]} rows: k-NN {100 * c["knn"]:.0f} % / static {100 * c["static"]:.0f} % (noise-aware '
            f'{100 * c["knn_noise"]:.0f} % / {100 * c["static_noise"]:.0f} %)' for c in curve),
        '',
        'Learning curve, paired labels (learning_curve_paired.tsv): ' + ', '.join(
            f'{c["rows"]} rows: k-NN {100 * c["knn"]:.0f} % / static {100 * c["static"]:.0f} % (noise-aware '
            f'{100 * c["knn_noise"]:.0f} % / {100 * c["static_noise"]:.0f} %)' for c in curve_p),
        '',
        'Figures: fig5_1_decision_map.png, fig5_2_time_vs_rbw.png, fig5_3_operating_time.png, '
        'fig5_4_time_vs_rtt.png, fig5_5_battery.png, fig5_6_time.png.',
    ]
    if tw:
        lines.append('\nTraining set warnings: ' + '; '.join(tw))
    text = '\n'.join(lines) + '\n'
    report.write_text(os.path.join(args.out, 'campaign.md'), text)
    print(text, flush=True)
    return 0


# ---------------------------------------------------------------- local vs remote (thesis Figs. 5-5, 5-6)
THESIS_LR_BATTERY_PCT = -10.0       # remote vs local battery per task (thesis §5.1 on Figs. 5-5/5-6)
THESIS_LR_TIME_S = -2.4             # remote - local task time (2.8 %)


def write_local_remote(args: argparse.Namespace) -> int:
    """local_remote.md, fig5_5_battery.png and fig5_6_time.png in ``args.out`` from the rows of each slowdown
    (``<out>/slowdown_<s>/results.tsv``): mean and sd per placement of the completed runs, as the thesis's
    Figs. 5-5/5-6 (bars with different local CPU frequency)."""
    from cnr_mission.core.task import read_results
    from network_monitor.core.evaluation import OFFLOAD, ONLOAD
    from cnr_benchmarks.campaign import slowdown_dir
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
        fig.savefig(os.path.join(args.out, name), dpi=110)
        plt.close(fig)
    md = (f'# Local vs remote move_base (thesis Figs. 5-5, 5-6)\n\n'
          f'`launch_scripts/exp_local_remote.sh {" ".join(args.argv)}` ({len(bars)} slowdown(s) with rows in '
          f'`slowdown_<s>/results.tsv`, each with its `plan.yaml` and `session/`): {args.task}@{args.location}, the link '
          f'unrestricted, runs alternating local (every module on the robot) and remote (move_base migrated to '
          f'the cloud before the task), at each robot CPU slowdown (the robot\'s cgroup capped at 1/slowdown '
          f'CPU; the thesis compared local CPU frequencies). Mean (sd) of the completed runs.\n\n'
          + report.markdown_table(['robot slowdown (cap)', 'local done', 'remote done', 'T local [s]',
                                   'T remote [s]', 'remote − local T', 'B local', 'B remote',
                                   'remote vs local B'], table)
          + f'\n\nThesis (20 runs each, unrestricted network, 1.6 GHz): remote {THESIS_LR_BATTERY_PCT:g} % battery, '
          f'{THESIS_LR_TIME_S:g} s (−2.8 %) task time.\n\nFigures: fig5_5_battery.png, fig5_6_time.png.\n')
    report.write_text(os.path.join(args.out, 'local_remote.md'), md)
    print(md, flush=True)
    return 0
