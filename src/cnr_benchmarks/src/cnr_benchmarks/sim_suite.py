"""Benchmark the simulator and the navigation node; prints and saves the figures.

    launch_scripts/bench_sim.sh [--out DIR]        (default DIR: docs/results/sim)

Measures: simulator core real-time multiple without ROS (corridor, data-center), time per 640-beam
scan and per 80x60 depth frame, achieved real-time factor of the simulator node with ROS I/O as fast as
possible, time to plan across the data-center hall, navigation control-loop time, time to put a depth
frame into the local costmap, the depth stream's bandwidth and move_base's CPU per depth frame (the robot
brought up twice in real time, with and without the depth source: about 2.5 minutes), and what a move_base
start-up costs the master (parameter calls, registrations). Each part runs in a process of its own
(cnr_benchmarks.sim, .navigation, .depth, .startup_audit), writing its JSON to bench_results/sim/; then the
table goes to DIR/README.md and DIR/sim.tsv. Uses private rosmasters on free ports; stops everything it starts.
"""
from __future__ import annotations

import json
import os
import sys
from typing import Dict, List, Optional

from cnr_benchmarks import cli, report, results

PARTS = (('simulator', 'cnr_benchmarks.sim', 'sim.json'),
         ('navigation', 'cnr_benchmarks.navigation', 'navigation.json'),
         ('depth stream bandwidth and move_base CPU per depth frame', 'cnr_benchmarks.depth', 'depth.json'),
         ('move_base start-up on the master', 'cnr_benchmarks.startup_audit', 'move_base_startup.json'))


def verdict(value: float, target: str) -> str:
    """``pass``/``FAIL`` against a target ``>= N`` or ``<= N``; empty for any other target."""
    if target in ('-', '') or target.split()[0] not in ('>=', '<='):
        return ''
    op, num = target.split()[:2]
    return 'pass' if (value >= float(num) if op == '>=' else value <= float(num)) else 'FAIL'


def table_rows(figures: List[Dict], startup: Dict) -> List[List[str]]:
    """[quantity, measured, target, verdict] of the figures and of the move_base start-up audit."""
    rows = [[r['name'], f"{r['value']:.2f} {r['unit']}", r['target'], verdict(r['value'], r['target'])]
            for r in figures]
    rows += [['move_base start-up: parameter calls', str(startup['parameter_calls']),
              'about 390 (TurtleBot move_base)', ''],
             ['move_base start-up: registrations', str(startup['registrations']), 'about 50', ''],
             ['move_base start-up time (local master)', f"{startup['startup_seconds']:.2f} s", '-', '']]
    return rows


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('bench_sim.sh', __doc__)
    ap.add_argument('--out', default=results.results_dir('sim'), help="the page's folder (default %(default)s)")
    args = ap.parse_args(argv)
    scratch = results.scratch_dir('sim')
    os.makedirs(scratch, exist_ok=True)
    for label, module, name in PARTS:
        report.progress(f'[bench_sim.sh] {label} ({module})')
        rc = report.call([sys.executable, '-m', module, '--out', os.path.join(scratch, name)])
        if rc != 0:
            print(f'bench_sim.sh: {module} ended with status {rc}', file=sys.stderr)
            return rc
    figures = [r for _label, _module, name in PARTS[:3] for r in _load(os.path.join(scratch, name))]
    rows = table_rows(figures, _load(os.path.join(scratch, PARTS[3][2])))
    os.makedirs(args.out, exist_ok=True)
    results.write_tsv(os.path.join(args.out, 'sim.tsv'), ['quantity', 'measured', 'target', 'verdict'], rows)
    print(results.write_page(args.out, 'Simulator and navigation', 'thesis §3: Stage and move_base',
                             report.markdown_table(['quantity', 'measured', 'target', ''], rows),
                             cli.command(ap, argv)))
    return 0


def _load(path: str):
    with open(path) as f:
        return json.load(f)


if __name__ == '__main__':
    report.run_main(main)
