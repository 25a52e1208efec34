"""The split mission under a flapping link (root): seeded random outage schedules over the placements.

    launch_scripts/bench_flap.sh [--runs N] [--configs A,B,...] [--outages N] [--seed S] [--out DIR] [--fresh]

Each run is a real-time two-host mission in the corridor (run_mission.sh --two-host) while the bench plays a
seeded random outage schedule on the testbed's link (cnr_testbed.core.flap: cuts and loss bursts of 30-90 %,
0.2-15 s, gaps 0.5-20 s, both directions, robot -> cloud only and cloud -> robot only; default 20 events). The
schedule starts once the robot has published its first 30 measurements; the mission goes on after the hotspot
until the schedule has played (then the bench asks the mission monitor to finish). Run i of every configuration
plays the same schedule (seed S + i). Configurations (default: all):
  monitoring_cloud, paper_normal, move_base_cloud    the placement, fixed
  ...+migration                                        the same placement, modules managed by migration_manager
  network_aware                                        the network-aware main job (--network-aware)
While a run plays, both masters are polled (20 Hz) and, per outage, the restore is recorded (multimaster_bridge.watch):
each discrepancy between what a master holds of the other's registrations and what it should is timed from the
link's return, or from when it arose if later, until it is gone; the restore is the longest (and, beside it, the
time until the invariant held unbroken until the next outage). Per run, in
bench_results/flap/runs/<config>-<i>/: the mission's report, schedule.tsv, restore.tsv, watch.tsv (every change of the invariant's discrepancies, one per registration, wall time, with the poll before each), the mission's output
(<folder>.log). Resumable: a run whose summary.json exists is kept (--fresh starts over). Then the page
docs/results/flap/README.md (or DIR) and runs.tsv. About 5 minutes per run.
"""
from __future__ import annotations

import functools
import os
import shutil
import subprocess
import time
from typing import List, Optional

import yaml

from cnr_benchmarks import cli, report, results
from cnr_benchmarks.core import flap as core
from cnr_testbed.api import Testbed
from cnr_testbed.core.flap import Outage, onset, schedule

EXPERIMENT = 'flap'
RUN_MISSION = os.path.join(results.WS, 'launch_scripts', 'run_mission.sh')
TESTBED_CONFIG = os.path.join(results.WS, 'config', 'testbed.yaml')
SCENARIO = os.path.join(results.WS, 'config', 'scenarios', 'corridor.yaml')
STARTED = 'measurements; latest'       # the mission monitor's progress line every 30 measurements
FOUND = 'hotspot found in'
START_LIMIT = 420.0                    # s for the mission to come up (migration: modules start under the CPU cap)
MASTER_PORT = 11311                    # the two-host mission's masters (run_mission.sh --port default)
END_LIMIT = 900.0                      # s after the schedule for the mission to end
CLEAR = {'outage': False, 'loss': 0.0}


def scenario_file(folder: str) -> str:
    """The corridor with an extra time after the hotspot long enough for any schedule (the bench finishes the
    mission itself once the schedule has played)."""
    with open(SCENARIO) as f:
        sc = yaml.safe_load(f)
    sc['mission']['extra_time'] = END_LIMIT + 3600.0
    path = folder + '.scenario.yaml'
    with open(path, 'w') as f:
        f.write('# the corridor for bench_flap.sh: the mission ends when the bench asks (~finish)\n')
        yaml.safe_dump(sc, f, sort_keys=False)
    return path


def wait_for_line(log_path: str, text: str, proc: subprocess.Popen, limit: float) -> bool:
    """Wait (bounded) until ``text`` appears in the log; False when the process ended or the limit passed."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline and proc.poll() is None:
        with open(log_path, errors='replace') as f:
            if text in f.read():
                return True
        time.sleep(1.0)
    return False


def play(tb: Testbed, events: List[Outage], watch) -> List[dict]:
    """Play ``events`` on the testbed's link in real time; their wall-clock start and end times."""
    t0 = time.monotonic()
    played = []
    for i, e in enumerate(events):
        time.sleep(max(0.0, t0 + e.start - time.monotonic()))
        tb.set(e.direction, **onset(e))
        wall_start = time.time()
        watch.outage_began()
        time.sleep(max(0.0, t0 + e.end - time.monotonic()))
        tb.set(e.direction, **CLEAR)
        wall_end = time.time()
        watch.outage_ended()
        played.append(dict(index=i, start=e.start, duration=e.duration, direction=e.direction, kind=e.kind,
                           loss=e.loss, wall_start=wall_start, wall_end=wall_end))
        report.progress(f'  outage {i + 1}/{len(events)}: {e.describe()}')
    return played


def finish_mission(tb: Testbed, port: int) -> None:
    """Ask the robot's mission monitor to write its report and end (``~finish``)."""
    env = dict(os.environ, ROS_MASTER_URI=f'http://{tb.robot_address}:{port}', ROS_IP=tb.robot_address)
    tb.exec_in('robot', ['rosservice', 'call', '/mission_monitor/finish'], env=env, capture_output=True,
               timeout=30)


def restore_watch(tb: Testbed, folder: str, port: int):
    """Both masters of the testbed, polled from their namespaces against the bridges' configurations the mission
    wrote (config/bridge.yaml overlaid by the host's allow-lists in ``<folder>/logs``)."""
    from cnr_testbed.netns import inside
    from multimaster_bridge.watch import RestoreWatch
    shared = os.path.join(results.WS, 'config', 'bridge.yaml')
    return RestoreWatch(f'http://{tb.robot_address}:{port}', f'http://{tb.cloud_address}:{port}',
                        [shared, os.path.join(folder, 'logs', 'bridge_robot.yaml')],
                        [shared, os.path.join(folder, 'logs', 'bridge_cloud.yaml')],
                        robot_netns=tb.namespace('robot'), cloud_netns=tb.namespace('cloud'), enter=inside)


def run_one(tb: Testbed, config: str, folder: str, events: List[Outage], port: int = MASTER_PORT) -> int:
    """One mission of ``config`` under ``events`` on the (running) testbed ``tb``, its masters on ``port``; its exit
    status (a failed run leaves no summary.json)."""
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(os.path.dirname(folder), exist_ok=True)
    argv = [RUN_MISSION, *core.mission_args(config), '--scenario', scenario_file(folder), '--delay', '0',
            '--port', str(port), '--report-dir', folder]
    log_path = f'{folder}.log'
    with open(log_path, 'w') as log:
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT)
    played: List[dict] = []
    watch = None
    try:
        if not wait_for_line(log_path, STARTED, proc, START_LIMIT):
            report.progress(f'  the mission did not start (see {log_path})')
        else:
            watch = restore_watch(tb, folder, port).start()
            played = play(tb, events, watch)
            time.sleep(5.0)                   # the last outage's restore
            watch.stop()
            if wait_for_line(log_path, FOUND, proc, END_LIMIT):
                finish_mission(tb, port)
        status = proc.wait(timeout=END_LIMIT)
    except KeyboardInterrupt:
        proc.terminate()
        proc.wait()
        raise
    except subprocess.TimeoutExpired:
        proc.terminate()
        status = proc.wait()
    finally:
        if watch is not None:
            watch.stop()
        tb.set('both', **CLEAR)
    os.makedirs(folder, exist_ok=True)
    results.write_tsv(os.path.join(folder, 'schedule.tsv'), core.SCHEDULE_COLUMNS,
                      [[p[c] for c in core.SCHEDULE_COLUMNS] for p in played])
    restored = watch.results() if watch is not None else None
    results.write_tsv(os.path.join(folder, 'restore.tsv'), core.RESTORE_COLUMNS,
                      [[i, p['wall_end'], r, lag, '; '.join(problems[:3])] for i, (p, r, lag, problems) in
                       enumerate(zip(played, restored.restores, restored.lags, restored.last_problems))]
                      if restored else [])
    if watch is not None:
        to_wall = time.time() - time.monotonic()
        results.write_tsv(os.path.join(folder, 'watch.tsv'), core.WATCH_COLUMNS,
                          [[f'{t + to_wall:.3f}', int(not wrong), '; '.join(wrong)] for t, wrong in watch.changes()])
    with open(os.path.join(folder, 'status'), 'w') as f:
        f.write(f'{status}\n')
    if status == report.EXIT_INTERRUPTED:
        raise KeyboardInterrupt
    if status not in (0, 3) or not played:
        summary = os.path.join(folder, 'summary.json')
        if os.path.exists(summary):
            os.remove(summary)
    return status


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('bench_flap.sh', __doc__)
    ap.add_argument('--runs', type=cli.positive_int, default=3, help='runs per configuration (default %(default)s)')
    ap.add_argument('--configs', type=cli.comma_list(list(core.CONFIGS)), default=','.join(core.CONFIGS),
                    help='comma-separated configurations (default: all)')
    ap.add_argument('--outages', type=cli.positive_int, default=20, help='events per schedule (default %(default)s)')
    ap.add_argument('--seed', type=int, default=1, help='run i plays the schedule of seed SEED + i (default %(default)s)')
    report.add_resumable_arguments(ap, EXPERIMENT)
    args = ap.parse_args(argv)
    scratch = report.resumable_scratch(ap.prog, args, EXPERIMENT)
    tb = Testbed(TESTBED_CONFIG)
    brought_up = not tb.running()
    if brought_up:
        tb.up()
    t0 = time.monotonic()
    folder_of = functools.partial(core.run_folder, scratch)
    try:
        for i, config, folder, prefix in report.pending_runs(ap.prog, args.runs, args.configs, folder_of):
            events = schedule(args.seed + i, args.outages)
            report.progress(f'{prefix} {config} run {i} ({len(events)} outages over {events[-1].end:.0f} s), '
                            f'{time.monotonic() - t0:.0f} s so far')
            status = run_one(tb, config, folder, events)
            run = core.load_run(folder, config, i)
            report.progress(f'[{ap.prog}] {config} run {i}: status {status}; ' +
                            ('no report' if run is None else
                             ('goal line met' if not run.goal_failures() else '; '.join(run.goal_failures()))))
    finally:
        if brought_up:
            tb.down()
    runs = report.finished_runs(args.runs, args.configs, folder_of, core.load_run)
    rows = [r.row() for r in runs]
    results.write_page(args.out, 'The split mission under a flapping link', 'thesis §4.2: unstable networks',
                       core.page_body(runs, args.outages, args.seed), cli.command(ap, argv),
                       tables={'runs.tsv': (list(rows[0]), rows)} if rows else None)
    report.progress(f'[{ap.prog}] done in {time.monotonic() - t0:.0f} s: {args.out}/README.md, runs.tsv')
    return 0


if __name__ == '__main__':
    report.run_main(main, 'the finished runs are kept; run the same command again to resume')
