"""The paper's dead-zone experiment (thesis Appendix VI, Fig. 10-11), on the testbed (root).

    launch_scripts/exp_deadzone.sh [--runs N] [--modes normal,network_aware[,normal_uplink]] [--out DIR] [--fresh]

The corridor (config/scenarios/deadzone.yaml: 2 m x 12 m, a pair of heaters, the global goal module's Z
route) with Wi-Fi only near both ends (the link follows the robot's position); N runs per mode (default 5),
alternating (default modes normal and network_aware):
  normal         GG and MFG on the cloud (placement paper_normal), dead zone cuts both directions
                 (config/link_map_corridor.yaml)
  network_aware  GG on the cloud, MFG on the robot (paper_network_aware), the same dead zone
  normal_uplink  as normal, but the dead zone cuts robot -> cloud only (config/link_map_corridor_uplink.yaml):
                 the paper's own description of its normal run ("sensor data does not reach the MFG")
Each run is a real-time two-host mission (run_mission.sh --two-host) with its report in
bench_results/deadzone/runs/<mode>-<i>/ and its output in bench_results/deadzone/runs/<mode>-<i>.log.
Resumable: a run whose summary.json exists is kept (--fresh starts over). Then docs/results/deadzone/ (or DIR):
runs.tsv, the page README.md (time and measurements to the hotspot, median and spread, beside the paper's ~100
measurements / ~33 s; the MFG's longest idle time) and deadzone.png (temperature vs measurement number, the
paper's plot). About 2 minutes per run.
"""
from __future__ import annotations

import functools
import os
import shutil
import time
from typing import List, Optional

from cnr_benchmarks import cli, report, results
from cnr_benchmarks.core import deadzone

EXPERIMENT = 'deadzone'
RUN_MISSION = os.path.join(results.WS, 'launch_scripts', 'run_mission.sh')
MISSION_ENDED = (0, 3)          # run_mission's statuses of a mission that ended with its report (3: timed out)


def run_one(mode: str, folder: str) -> int:
    """One two-host mission of ``mode`` with its report in ``folder`` and its output in ``<folder>.log``; returns
    its exit status (a run that failed leaves no summary.json behind)."""
    placement, link_map = deadzone.MODES[mode]
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(os.path.dirname(folder), exist_ok=True)
    with open(f'{folder}.log', 'w') as log:
        status = report.call([RUN_MISSION, '--two-host', '--scenario', 'deadzone', '--placement',
                              placement, '--link-map', os.path.join(results.WS, 'config', link_map),
                              '--report-dir', folder], log)
    if status == report.EXIT_INTERRUPTED:
        raise KeyboardInterrupt
    if status not in MISSION_ENDED:
        summary = os.path.join(folder, 'summary.json')
        if os.path.exists(summary):
            os.remove(summary)
    return status


def last_result_line(log_path: str) -> str:
    """The mission's last 'hotspot found in' or 'timeout after' line, or ''."""
    with open(log_path, errors='replace') as f:
        lines = [ln.rstrip('\n') for ln in f if 'hotspot found in' in ln or 'timeout after' in ln]
    return lines[-1] if lines else ''


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('exp_deadzone.sh', __doc__)
    ap.add_argument('--runs', type=cli.positive_int, default=5, help='runs per mode (default %(default)s)')
    ap.add_argument('--modes', type=cli.comma_list(list(deadzone.MODES)), default='normal,network_aware',
                    help='comma-separated modes (default %(default)s)')
    report.add_resumable_arguments(ap, EXPERIMENT)
    args = ap.parse_args(argv)
    scratch = report.resumable_scratch(ap.prog, args, EXPERIMENT)
    t0 = time.monotonic()
    for i, mode, folder, prefix in report.pending_runs(ap.prog, args.runs, args.modes,
                                                       functools.partial(deadzone.run_folder, scratch)):
        report.progress(f'{prefix} {mode} run {i} ({deadzone.MODES[mode][0]}), {time.monotonic() - t0:.0f} s so far')
        status = run_one(mode, folder)
        if status in MISSION_ENDED:
            report.progress(last_result_line(f'{folder}.log'))
        else:
            report.progress(f'[{ap.prog}] {mode} run {i} failed (status {status}; see {folder}.log)')
    runs = report.finished_runs(args.runs, args.modes, functools.partial(deadzone.run_folder, scratch),
                                deadzone.load_run)
    print(deadzone.write_outputs(args.out, runs, cli.command(ap, argv)))
    report.progress(f'[{ap.prog}] done in {time.monotonic() - t0:.0f} s: {args.out}/README.md, deadzone.png, runs.tsv')
    return 0


if __name__ == '__main__':
    report.run_main(main, 'the finished runs are kept; run the same command again to resume')
