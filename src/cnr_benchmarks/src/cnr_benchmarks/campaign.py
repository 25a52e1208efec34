"""The control experiment (exp_control.sh) and the continuous experiment (exp_campaign.sh) of thesis §5 (root).

    /usr/bin/python3 -m cnr_benchmarks.campaign control [--runs 20] [--out DIR]       (launch_scripts/exp_control.sh)
    /usr/bin/python3 -m cnr_benchmarks.campaign campaign [--conditions 100] [--seed 1] [--out DIR] [--analyse-only]
                                                                                       (launch_scripts/exp_campaign.sh)
    /usr/bin/python3 -m cnr_benchmarks.campaign analyse [--out DIR]
    /usr/bin/python3 -m cnr_benchmarks.campaign local_remote [--runs 20] [--slowdowns 3,6]

Both run the two-host testbed in task mode (``two_host_mission --task-plan``): one session, the task_runner
runs the plan's tasks one after the other (config/scenarios/<location>.yaml ``tasks``), move_base managed by
migration_manager and placed by network_monitor's migration_decider. Rows are appended as measured; running the
same command again resumes after the last finished run.

``control``: every module on the robot, no decision; CT/CB (mean, sd of the completed runs) are written to
config/control_values.yaml (or ``--control-values``) and printed beside the thesis's Table 4-5. A task that is
not one of the location's ``tasks`` but a monitoring mission of config/decision.yaml (``patrol``,
``hotspot_search``: the main job's decision) is measured as the main job measures it: ``--runs`` whole two-host
missions (placement all_robot, the modules run by migration agents as in the main job, no decider, the link of
``--link-map``, default config/link_map_<location>.yaml when there is one), T_task the sim time to the hotspot
and B_task the battery used until then (the mission report's ``task``); each run in ``<scratch>/runs/NN``.

``campaign``: ``--conditions`` link conditions drawn with ``--seed`` (cnr_benchmarks.core.campaign), each
profiled once with the modules on the robot, decided by the robot's policy and run onload then offload; the
robot's training set starts empty in ``<scratch>/training`` (cold start, then k-NN as it learns). Then
``analyse``: the learning curve against the oracle beside the best static threshold, Figures 5-1 to 5-6 and
campaign_summary.json (the learned decision's measures on the held-out conditions beside the a-priori rules and the
hindsight thresholds, and the figures' numbers: cnr_benchmarks.core.decision_measures) in ``<out>/``, with the page
README.md. Without ``<scratch>/training`` the analysis reads the robot's set published beside the rows
(``<out>/training_set.tsv``).

``local_remote`` (thesis Figs. 5-5/5-6): ``--runs`` runs local and as many remote (move_base on the cloud),
alternating, on the unrestricted link, at each robot CPU slowdown of ``--slowdowns`` (the thesis compared local
CPU frequencies); the page README.md and the two figures. ``--slowdown S`` runs control or campaign with the robot
capped at 1/S CPU: on a copy of config/ in ``<scratch>/slowdown_<S>`` whose testbed.yaml says so.

All three run on a copy of config/ in the scratch with config/task_experiments.yaml's values set (move_base also
dormant on the cloud: an offload wakes it instead of starting a clone).

``<out>``: the page and its rows, default docs/results/<experiment>/; ``<scratch>``: the sessions' logs,
plans, runs and training sets, bench_results/<experiment>/ (with ``--out``: the same folder).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import sys
import time
from typing import Dict, List, Optional

import yaml

from cnr_benchmarks import cli, report, results
from cnr_benchmarks.campaign_figures import COMMAND_FILE, write_analysis, write_local_remote
from cnr_benchmarks.core import campaign as core
from cnr_benchmarks.session import run_session, slowdown_dir, task_config, testbed_running, two_host_argv
from cnr_params.files import write_atomic

THESIS_CT, THESIS_CT_SD = 87.9286, 14.3815          # s, Table 4-5
THESIS_CB, THESIS_CB_SD = 0.004586, 0.000702        # battery fraction, Table 4-5

CONTROL_DOC = """The control experiment of thesis Table 4-5.

    launch_scripts/exp_control.sh [--runs 20] [--task T] [--location L] [--out DIR] [--control-values FILE]
                                  [--settle 6] [--port 11411] [--link-map FILE] [--slowdown S] [--from-rows FILE]

--runs runs (default 20) of the task (default corridor_round_trip@corridor: config/scenarios/corridor.yaml tasks) on
the two-host testbed with every module on the robot and no decision; CT (task time) and CB (battery fraction) as mean
and sd of the completed runs are written to config/control_values.yaml (Eq. 4-5's control values) and printed beside
the thesis's CT 87.9286 s (sd 14.3815), CB 0.004586 (sd 0.000702). Needs root; uses the default testbed (robot/cloud
namespaces). The page and the rows (results.tsv, appended as measured: run it again to resume) go to
docs/results/control/<task>@<location>/ (or DIR); the sessions' logs to bench_results/control/<task>@<location>/.
--task patrol (or hotspot_search: a monitoring mission of config/decision.yaml, the main job's decision) runs whole
two-host missions instead, as the main job measures them (T to the hotspot, B until then), with the link of
--link-map (default config/link_map_<location>.yaml); about 4 minutes each.

--slowdown S measures them with the robot's CPU capped at 1/S (default config/testbed.yaml's robot_cpu.slowdown):
written to docs/results/control/control_values_slowdown<S>.yaml, the page in
docs/results/control/<task>@<location>_slowdown<S>/. --from-rows FILE runs nothing: the control values of the
all-local runs of a results TSV, e.g. the onload runs of exp_local_remote.sh
(docs/results/local_remote/slowdown_<S>/results.tsv: the same task, every module local).
"""

CAMPAIGN_DOC = """The continuous experiment of thesis §5.

    launch_scripts/exp_campaign.sh [--conditions 100] [--seed 1] [--out DIR] [--test-fraction 0.3]
                                   [--held-out-repeats 2] [--rtt-min 0 --rtt-max 250 --rate-min 0.5 --rate-max 50 --loss-min 0
                                    --loss-max 0.1] [--settle 6] [--port 11411] [--slowdown S] [--task T1[,T2...]]
    launch_scripts/exp_campaign.sh --analyse-only [--out DIR] [--exclude c0017,...]

--conditions link conditions (default 100; RTT 0-250 ms, rate 0.5-50 Mbit/s log-uniform, loss 0-10 %, drawn with
--seed) on the two-host testbed, each profiled once with move_base on the robot and decided by network_monitor's
migration_decider (k-NN), then run onload and offload on that profile; both runs evaluated (Eq. 4-5) and learned from
an empty training set. Then the analysis: the decisions against the oracle of the paired runs, the learning curve
beside the best static threshold, Figures 5-1 to 5-6 beside the thesis's numbers and campaign_summary.json (k-NN
accuracy with <= 40 rows per task against the noise-aware oracle, regret against the a-priori rules, the best
hindsight threshold, the crossings; a value the rows cannot give is null and the page says why), in
docs/results/campaign/ (or DIR; with --slowdown S: docs/results/campaign_slowdown<S>/); the sessions' logs and the
training set in bench_results/campaign[_slowdown<S>]/ (without it the analysis reads DIR/training_set.tsv). Needs
the control values (exp_control.sh) and root; uses the default testbed. Rows are appended as measured; run it again
to resume. About 66 s per condition. --slowdown S: the robot's CPU capped at 1/S instead of config/testbed.yaml's,
with the control values of exp_control.sh --slowdown S.
--held-out-repeats R: a learning plan instead of pairs: each training condition is run once, in the placement the
robot's policy chooses (with exploration), and learned, as a robot in service learns; each held-out condition (ids
h0071, ...) R times per placement, never learned, for the noise-aware oracle's repeats.
--task T1,T2: several tasks of the location in one session, the conditions dealt to them in turn (each task's last
--test-fraction held out), each learned per <task, location> (thesis §4.2.5); Figures 5-1 to 5-6 show T1's runs,
campaign_summary.json every task's. Each task's training set is copied beside the rows after the session.
--analyse-only: the analysis and figures of the rows so far (--exclude: conditions left out, named on the page).
"""

LOCAL_REMOTE_DOC = """Thesis Figs. 5-5 and 5-6: local vs remote move_base on an unrestricted link.

    launch_scripts/exp_local_remote.sh [--runs 20] [--slowdowns 3,6] [--out DIR] [--task T] [--location L]
                                       [--port 11411]
    launch_scripts/exp_local_remote.sh --analyse-only [--slowdowns 3,6] [--out DIR]   # table and figures only

The task (default corridor_round_trip@corridor) --runs times with every module on the robot and --runs times with
move_base on the cloud (alternating), on the unrestricted link, at each robot CPU slowdown of --slowdowns (default
config/testbed.yaml's robot_cpu.slowdown and twice it: the thesis compared local CPU frequencies). Battery and time
per task, mean and sd, beside the thesis's (remote -10 % battery, -2.4 s): the page and its figures in
docs/results/local_remote/ (or DIR), the rows in its slowdown_<s>/results.tsv (appended as measured: run it again to
resume), the sessions' logs in bench_results/local_remote/. Needs root and no running testbed. About 25 s per run.
"""

SCRIPTS = {'control': ('exp_control.sh', CONTROL_DOC), 'campaign': ('exp_campaign.sh', CAMPAIGN_DOC),
           'analyse': ('exp_campaign.sh --analyse-only', CAMPAIGN_DOC),
           'local_remote': ('exp_local_remote.sh', LOCAL_REMOTE_DOC)}


# ---------------------------------------------------------------- control (Table 4-5)
def control(args: argparse.Namespace) -> int:
    from cnr_mission.core.task import read_results
    scenario = os.path.join(report.WS, 'config', 'scenarios', f'{args.location}.yaml')
    with open(scenario) as f:
        goal_tasks = (yaml.safe_load(f) or {}).get('tasks') or {}
    if args.task not in goal_tasks:
        return control_missions(args, scenario)
    if args.from_rows:
        return control_from_rows(args)
    rows_path = os.path.join(args.out, 'results.tsv')
    plan = core.control_plan(args.task, args.location, args.settle, args.runs)
    rc = run_session(args, plan, rows_path, os.path.join(args.scratch, 'training'), args.control_values)
    rows, _ = read_results(rows_path)
    return write_control(args, rows) or rc


def control_from_rows(args: argparse.Namespace) -> int:
    """The control values of runs already made with every module on the robot (``--from-rows``: a results TSV,
    e.g. exp_local_remote.sh's onload runs at the same slowdown): its rows forced onload or not forced."""
    from cnr_mission.core.task import read_results
    from network_monitor.core.evaluation import ONLOAD
    if not os.path.exists(args.from_rows):
        print(f'exp_control: --from-rows: no such file {args.from_rows}', file=sys.stderr)
        return 2
    rows, warnings = read_results(args.from_rows)
    for w in warnings:
        print(w, file=sys.stderr)
    local = [r for r in rows if r.get('force') in ('', ONLOAD)]
    report.progress(f'[control] {len(local)} all-local runs of {len(rows)} in {args.from_rows}')
    return write_control(args, local)


def write_control(args: argparse.Namespace, rows: List[Dict]) -> int:
    """CT/CB of the completed rows (mission_status, t_task, b_task) into the control values and the page."""
    from cnr_mission.core.task import COMPLETED
    from network_monitor.core.evaluation import ControlValues, write_control_values
    done = [r for r in rows if r['mission_status'] == COMPLETED]
    report.progress(f'[control] {len(rows)} runs, {len(done)} completed')
    if len(done) < 2:
        print('exp_control: fewer than 2 completed runs: no control values written', file=sys.stderr)
        return 1
    t = [float(r['t_task']) for r in done]
    b = [float(r['b_task']) for r in done]
    values = ControlValues(task=args.task, ct_mean=statistics.mean(t), ct_std=statistics.stdev(t),
                           cb_mean=statistics.mean(b), cb_std=statistics.stdev(b), runs=len(done),
                           date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds'),
                           command='launch_scripts/exp_control.sh ' + ' '.join(args.argv))
    write_control_values(args.control_values, values)
    table = report.markdown_table(
        ['', 'runs', 'CT [s] mean (sd)', 'CB [fraction] mean (sd)'],
        [['thesis Table 4-5 (88 s corridor round trip)', 20, f'{THESIS_CT:.4f} ({THESIS_CT_SD:.4f})',
          f'{THESIS_CB:.6f} ({THESIS_CB_SD:.6f})'],
         [f'measured ({args.task}@{args.location})', len(done), f'{values.ct_mean:.2f} ({values.ct_std:.2f})',
          f'{values.cb_mean:.6f} ({values.cb_std:.6f})']])
    body = (f'Measured {values.date}; every module on the robot, {len(rows)} runs, {len(done)} completed. Written '
            f'to `{args.control_values}`.\n\n{table}\n')
    print(results.write_page(args.out, 'Control values CT and CB', 'thesis Table 4-5', body, values.command),
          flush=True)
    return 0


def control_missions(args: argparse.Namespace, scenario: str) -> int:
    """The control runs of a monitoring-mission task (module docstring): one two-host mission per run."""
    from network_monitor.core.decision_config import load_decision_config
    if args.task not in load_decision_config(os.path.join(report.WS, 'config', 'decision.yaml')).tasks:
        print(f'exp_control: {args.task!r} is neither a task of {scenario} (tasks) nor of config/decision.yaml '
              f'(tasks)', file=sys.stderr)
        return 2
    link_map = args.link_map
    if link_map is None:
        default = os.path.join(report.WS, 'config', f'link_map_{args.location}.yaml')
        link_map = default if os.path.exists(default) else ''
    runs_dir = os.path.join(args.scratch, 'runs')
    rows: List[Dict] = []
    for i in range(1, args.runs + 1):
        run = os.path.join(runs_dir, f'{i:02d}')
        summary = os.path.join(run, 'summary.json')
        if not os.path.exists(summary):
            report.move_aside(run)              # an interrupted run: kept aside, never reloaded
            report.progress(f'[control] run {i}/{args.runs}: {args.task}@{args.location} mission, every module on '
                            f'the robot' + (f', link map {os.path.relpath(link_map, report.WS)}' if link_map else ''))
            argv = two_host_argv(args.location, run, args.port, getattr(args, 'cfg_dir', None))
            if argv is None:
                return 2
            rc = report.call(argv + ['--migration'] + (['--link-map', link_map] if link_map else []))
            if rc not in (0, 3) or not os.path.exists(summary):
                print(f'exp_control: run {i} ended with status {rc} and no report ({run}); run the same command '
                      f'again to resume', file=sys.stderr)
                return rc or 1
        with open(summary) as f:
            task = json.load(f)['task']
        if task['b_task'] is None:
            print(f'exp_control: run {i} has no battery reading ({summary}): left out', file=sys.stderr)
            continue
        rows.append(dict(id=f'control-{i:02d}', mission_status=task['mission_status'], t_task=task['t_task'],
                         b_task=task['b_task']))
        report.progress(f'[control] run {i}: {task["mission_status"]}, T {task["t_task"]:.1f} s, '
                        f'B {task["b_task"]:.5f}')
    os.makedirs(args.out, exist_ok=True)            # a table of the runs' reports (rewritten)
    columns = ['id', 'mission_status', 't_task', 'b_task']
    results.write_tsv(os.path.join(args.out, 'results.tsv'), columns,
                      [[str(r[c]) for c in columns] for r in rows])
    return write_control(args, rows)


# ---------------------------------------------------------------- local vs remote (Figs. 5-5, 5-6)
def local_remote(args: argparse.Namespace) -> int:
    if testbed_running('exp_local_remote'):
        return 2
    rc = 0
    for s in args.slowdowns:
        out = slowdown_dir(args.out, s)
        scratch = slowdown_dir(args.scratch, s)
        report.progress(f'[local_remote] robot CPU slowdown {s:g} (cap {1 / s:.3g} CPU): {args.runs} runs local and '
                        f'{args.runs} remote, alternating; rows in {out}/results.tsv')
        plan = core.local_remote_plan(args.task, args.location, args.settle, args.runs)
        os.makedirs(out, exist_ok=True)
        rc = run_session(args, plan, os.path.join(out, 'results.tsv'), os.path.join(scratch, 'training'),
                         args.control_values, scratch=scratch, cfg_dir=task_config(args.scratch, s))
        if rc != 0:
            print(f'exp_local_remote: the session at slowdown {s:g} ended with status {rc}; run the same command '
                  f'again to resume', file=sys.stderr)
            break
    return write_local_remote(args) or rc


# ---------------------------------------------------------------- campaign
def campaign(args: argparse.Namespace) -> int:
    ranges = core.Ranges(args.rtt_min, args.rtt_max, args.rate_min, args.rate_max, args.loss_min, args.loss_max)
    conditions = core.assign_tasks(core.draw_conditions(args.conditions, args.seed, ranges), args.tasks)
    if args.held_out_repeats:
        plan = core.learning_plan_document(args.task, args.location, args.settle,
                                           core.learning_split(conditions, args.test_fraction), args.held_out_repeats)
    else:
        plan = core.plan_document(args.task, args.location, args.settle, conditions)
    plan['seed'] = args.seed
    rows_path = os.path.join(args.out, 'results.tsv')
    os.makedirs(args.out, exist_ok=True)         # the command that made the rows, for a later --analyse-only
    write_atomic(os.path.join(args.out, COMMAND_FILE), 'launch_scripts/exp_campaign.sh ' + ' '.join(args.argv))
    t0 = time.monotonic()
    rc = run_session(args, plan, rows_path, os.path.join(args.scratch, 'training'), args.control_values)
    report.progress(f'[campaign] session ended with status {rc} after {(time.monotonic() - t0) / 60:.1f} min')
    publish_training_sets(args)
    return analyse(args) or rc


def publish_training_sets(args: argparse.Namespace) -> None:
    """Each task's training set as the robot learned it, copied beside the rows (the analysis reads it there when
    the scratch is gone): training_set.tsv for the first task, training_set_<task>.tsv for the others."""
    import shutil
    from cnr_benchmarks.campaign_figures import published_training
    from network_monitor.core.training import TrainingSet
    for task in args.tasks:
        src = TrainingSet(os.path.join(args.scratch, 'training'), task, args.location).path
        if os.path.exists(src):
            shutil.copyfile(src, published_training(args, task))


def analyse(args: argparse.Namespace) -> int:
    return write_analysis(args)


def parse_args(argv: Optional[List[str]]) -> argparse.Namespace:
    ap = cli.Parser('python3 -m cnr_benchmarks.campaign', __doc__)
    sub = ap.add_subparsers(dest='cmd', required=True)
    parsers = {}
    for name in ('control', 'campaign', 'analyse', 'local_remote'):
        script, doc = SCRIPTS[name]
        p = parsers[name] = sub.add_parser(name, prog=script, doc=doc)
        p.add_argument('--task', default='corridor_round_trip',
                       help='a task of config/decision.yaml' + (' (several, comma-separated: the conditions dealt '
                                                                 'to them in turn, the first one\'s figures)'
                                                                 if name in ('campaign', 'analyse') else ''))
        p.add_argument('--location', default='corridor', help='config/scenarios/<location>.yaml')
        p.add_argument('--out', default=None, help="the page's folder (default docs/results/control/<task>@<location>"
                                                   ", docs/results/campaign[_slowdown<S>], docs/results/local_remote;"
                                                   " the runs' scratch then in bench_results/, else in the folder)")
        p.add_argument('--port', type=int, default=11411, help='master port in both namespaces')
        p.add_argument('--settle', type=float, default=6.0,
                       help='s after setting a link before profiling (the network monitor window is 5 s)')
        p.add_argument('--control-values', default=None, help='default config/control_values.yaml')
        if name == 'local_remote':
            p.add_argument('--runs', type=int, default=20, help='runs per placement and slowdown')
            p.add_argument('--slowdowns', default=None,
                           help='robot CPU slowdowns, comma-separated (default: config/testbed.yaml\'s and twice it)')
            p.add_argument('--analyse-only', action='store_true', help='the table and figures of the rows so far')
        else:
            p.add_argument('--slowdown', type=float, default=None,
                           help="the robot's CPU slowdown (default config/testbed.yaml's); another one runs on a "
                                "copy of config/ in the scratch's slowdown_<s> and its control values default to "
                                "docs/results/control/control_values_slowdown<s>.yaml")
        if name == 'campaign':
            p.add_argument('--analyse-only', action='store_true',
                           help='the analysis and figures of the rows so far (runs nothing)')
        if name == 'control':
            p.add_argument('--runs', type=int, default=20)
            p.add_argument('--from-rows', default=None,
                           help='no runs: the control values of the all-local rows of this results TSV (e.g. '
                                'exp_local_remote.sh\'s slowdown_<s>/results.tsv)')
            p.add_argument('--link-map', default=None,
                           help="a monitoring-mission task's link map (default config/link_map_<location>.yaml)")
        else:
            p.add_argument('--conditions', type=int, default=100)
            p.add_argument('--seed', type=int, default=1)
            p.add_argument('--test-fraction', type=float, default=0.3, help='conditions held out (the last ones)')
            p.add_argument('--held-out-repeats', type=int, default=0,
                           help='a learning plan: each training condition run once in the placement the robot '
                                'chooses (exploring) and learned, each held-out one this many times per placement '
                                'and never learned (0: every condition paired and learned)')
            p.add_argument('--exclude', default='', help='conditions left out of the analysis (comma-separated '
                                                         'ids, e.g. runs known to be corrupted; the page says so)')
            for k, v in (('rtt-min', 0.0), ('rtt-max', 250.0), ('rate-min', 0.5), ('rate-max', 50.0),
                         ('loss-min', 0.0), ('loss-max', 0.10)):
                p.add_argument(f'--{k}', type=float, default=v)
    args, extra = ap.parse_known_args(argv)
    ap = parsers[args.cmd]              # errors from here on name the script
    if extra:
        ap.error(f'unrecognized arguments: {" ".join(extra)}')
    args.tasks = [t for t in args.task.split(',') if t]
    if not args.tasks or (len(args.tasks) > 1 and args.cmd not in ('campaign', 'analyse')):
        ap.error(f'--task: expected one task, got {args.task!r}')
    args.task = args.tasks[0]           # the one whose runs the figures show
    args.argv = list(argv if argv is not None else sys.argv[1:])
    args.argv.remove(args.cmd)          # the script's own arguments (the subcommand is the script's choice)
    if args.cmd == 'analyse':
        args.argv.insert(0, '--analyse-only')       # exp_campaign.sh's spelling of the subcommand
    elif getattr(args, 'analyse_only', False) and args.cmd == 'campaign':
        args.cmd = 'analyse'
    suffix = f'_slowdown{args.slowdown:g}' if getattr(args, 'slowdown', None) is not None else ''
    experiment = (os.path.join('control', f'{args.task}@{args.location}{suffix}') if args.cmd == 'control' else
                  'local_remote' if args.cmd == 'local_remote' else f'campaign{suffix}')
    args.scratch = os.path.abspath(args.out or results.scratch_dir(experiment))
    args.out = args.out or results.results_dir(experiment)
    if args.cmd == 'local_remote':
        args.slowdowns = parse_slowdowns(ap, args.slowdowns)
    elif args.slowdown is not None and args.slowdown < 1.0:
        ap.error(f'--slowdown: expected a number >= 1 (1 = a whole core), got {args.slowdown:g}')
    if args.control_values is None:
        args.control_values = (os.path.join(report.WS, 'docs', 'results', 'control', f'control_values{suffix}.yaml')
                               if suffix else os.path.join(report.WS, 'config', 'control_values.yaml'))
    args.out = os.path.abspath(args.out)
    if getattr(args, 'runs', 2) < 2 or getattr(args, 'conditions', 1) < 1:
        ap.error('--runs must be >= 2 and --conditions >= 1')
    return args


def parse_slowdowns(ap: argparse.ArgumentParser, text: Optional[str]) -> List[float]:
    if text is None:
        from cnr_testbed.core.config import load_testbed
        s = load_testbed(os.path.join(report.WS, 'config', 'testbed.yaml')).robot_cpu.slowdown
        return [s, 2 * s]
    try:
        values = [float(v) for v in text.split(',') if v.strip()]
    except ValueError:
        ap.error(f'--slowdowns: expected comma-separated numbers, got {text!r}')
    if not values or any(v < 1.0 for v in values):
        ap.error(f'--slowdowns: expected numbers >= 1 (1 = a whole core), got {text!r}')
    return values


def main(argv: Optional[List[str]] = None) -> int:
    args = parse_args(argv)
    if args.cmd == 'local_remote' and args.analyse_only:
            return write_local_remote(args)
    runs_nothing = args.cmd == 'analyse' or (args.cmd == 'control' and getattr(args, 'from_rows', None))
    if not runs_nothing:
        cli.require_root(SCRIPTS[args.cmd][0], "the testbed's network namespaces, TUN devices and CPU cgroup")
    if args.cmd in ('control', 'campaign') and not runs_nothing:
        if args.slowdown is not None and testbed_running(f'exp_{args.cmd}'):
            return 2
        args.cfg_dir = task_config(args.scratch, args.slowdown)    # config/task_experiments.yaml's copy
    return {'control': control, 'campaign': campaign, 'analyse': analyse,
            'local_remote': local_remote}[args.cmd](args)


if __name__ == '__main__':
    report.run_main(main, 'the rows measured so far are kept; run the same command again to resume')
