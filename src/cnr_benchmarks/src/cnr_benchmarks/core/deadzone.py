"""The paper's dead-zone experiment (thesis Appendix VI, Fig. 11): runs, table and plot (ROS-free).

Each run is a two-host mission report folder (``summary.json``, ``measurements.tsv``) of one mode:
``normal`` (global goal and MFG on the cloud: placement ``paper_normal``) or ``network_aware`` (global goal on
the cloud, MFG on the robot: ``paper_network_aware``), with Wi-Fi only near both ends of the corridor.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np

from cnr_benchmarks import results
from cnr_maps.measurements import read_tsv

# mode: (placement, link map): the two modes of the paper, with the dead zone cutting both directions (the
# Wi-Fi-only-at-the-ends corridor), and the paper's "normal" run as it describes it (sensor data does
# not reach the MFG on the cloud, its commands still reach the robot: the dead zone cuts the uplink only)
MODES = {'normal': ('paper_normal', 'link_map_corridor.yaml'),
         'network_aware': ('paper_network_aware', 'link_map_corridor.yaml'),
         'normal_uplink': ('paper_normal', 'link_map_corridor_uplink.yaml')}
# the paper's result (Appendix VI, Fig. 11): the network-aware run found the hotspot "roughly around 100
# measurements; meaning around 33 seconds" earlier than the normal run
PAPER_DIFFERENCE_MEASUREMENTS = 100
PAPER_DIFFERENCE_SECONDS = 33.0


@dataclass
class Run:
    mode: str
    index: int
    folder: str
    found: bool
    time_to_hotspot: Optional[float]          # s of sim time from the start
    measurements_to_hotspot: Optional[int]
    longest_idle: Optional[float]             # s, mfg/activity
    longest_input_gap: Optional[float]        # s
    goal_wait_longest: Optional[float]        # s
    wall_time: Optional[float]                # s
    temperatures: List[float]

    def row(self) -> Dict:
        return dict(mode=self.mode, run=self.index, found=self.found, time_to_hotspot=self.time_to_hotspot,
                    measurements_to_hotspot=self.measurements_to_hotspot, longest_idle=self.longest_idle,
                    longest_input_gap=self.longest_input_gap, goal_wait_longest=self.goal_wait_longest,
                    measurements=len(self.temperatures), wall_time=self.wall_time, folder=self.folder)


def run_folder(out: str, mode: str, index: int) -> str:
    return os.path.join(out, 'runs', f'{mode}-{index:02d}')


def load_run(folder: str, mode: str, index: int) -> Optional[Run]:
    """A finished run (its summary.json exists), or None."""
    try:
        with open(os.path.join(folder, 'summary.json')) as f:
            s = json.load(f)
    except (OSError, ValueError):
        return None
    act = s.get('mfg_activity') or {}
    path = os.path.join(folder, 'measurements.tsv')
    temps = [m.temperature for m in read_tsv(path)] if os.path.exists(path) else []
    idle = act.get('longest_idle')
    if idle is not None:      # an MFG cut off from the robot at the end was idle at least that long
        idle = max(idle, act.get('unreachable_at_end') or 0.0)
    return Run(mode, index, folder, bool(s.get('found')), s.get('sim_time_to_find'), s.get('measurements_to_hotspot'),
               idle, act.get('longest_input_gap'), act.get('goal_wait_longest'),
               (s.get('two_host') or {}).get('wall_time_total'), temps)


def stats(values: Sequence[Optional[float]]) -> Dict[str, Optional[float]]:
    v = np.array([x for x in values if x is not None], dtype=float)
    if not v.size:
        return dict(n=0, median=None, q1=None, q3=None, min=None, max=None)
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return dict(n=int(v.size), median=float(med), q1=float(q1), q3=float(q3), min=float(v.min()), max=float(v.max()))


def _fmt(st: Dict, unit: str = '', digits: int = 1) -> str:
    if not st['n']:
        return '-'
    f = f'{{:.{digits}f}}'
    return (f"{f.format(st['median'])}{unit} (IQR {f.format(st['q1'])}–{f.format(st['q3'])}, "
            f"{f.format(st['min'])}–{f.format(st['max'])}, n={st['n']})")


def table(runs: Sequence[Run]) -> str:
    """Markdown: per mode, time and measurements to the hotspot and the MFG's longest idle time."""
    by = {m: [r for r in runs if r.mode == m] for m in MODES}
    lines = ['| mode | placement, link map | runs (found) | time to hotspot [s] | measurements to hotspot | '
             'MFG longest idle [s] | longest input gap [s] | longest goal wait [s] |',
             '|---|---|---|---|---|---|---|---|']
    for m, rs in by.items():
        if not rs:
            continue
        lines.append(f"| {m} | {MODES[m][0]}, {MODES[m][1]} | {len(rs)} ({sum(r.found for r in rs)}) | "
                     f"{_fmt(stats([r.time_to_hotspot for r in rs]))} | "
                     f"{_fmt(stats([r.measurements_to_hotspot for r in rs]), digits=0)} | "
                     f"{_fmt(stats([r.longest_idle for r in rs]), digits=2)} | "
                     f"{_fmt(stats([r.longest_input_gap for r in rs]), digits=2)} | "
                     f"{_fmt(stats([r.goal_wait_longest for r in rs]), digits=2)} |")
    a = stats([r.time_to_hotspot for r in by['network_aware']])
    am = stats([r.measurements_to_hotspot for r in by['network_aware']])
    lines.append('')
    for m in ('normal', 'normal_uplink'):
        n = stats([r.time_to_hotspot for r in by[m]])
        nm = stats([r.measurements_to_hotspot for r in by[m]])
        if n['n'] and a['n']:
            lines.append(f"Difference of the medians ({m} − network_aware, runs that found the hotspot): "
                         f"{n['median'] - a['median']:.1f} s and {nm['median'] - am['median']:.0f} measurements; "
                         f"the paper: ≈ {PAPER_DIFFERENCE_SECONDS:.0f} s and ≈ {PAPER_DIFFERENCE_MEASUREMENTS} "
                         f"measurements (one run each).")
        elif by[m] and a['n']:
            lines.append(f"{m}: no run found the hotspot within the scenario's timeout.")
    return '\n'.join(lines)


def plot(runs: Sequence[Run], path: str) -> None:
    """The paper's Fig. 11: temperature vs measurement number, the two modes (every run, the median-time one bold)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9, 4.5))
    styles = {'normal': dict(color='tab:gray', linestyle=':'), 'network_aware': dict(color='tab:red', linestyle='-'),
              'normal_uplink': dict(color='tab:blue', linestyle='--')}
    for mode in MODES:
        rs = [r for r in runs if r.mode == mode and r.temperatures]
        if not rs:
            continue
        times = [r.time_to_hotspot if r.time_to_hotspot is not None else float('inf') for r in rs]
        typical = rs[int(np.argsort(times)[len(rs) // 2])]
        for r in rs:
            if r is not typical:
                ax.plot(range(1, len(r.temperatures) + 1), r.temperatures, linewidth=0.6, alpha=0.3, **styles[mode])
        label = f"{mode.replace('_', '-')} ({MODES[mode][0]}, run {typical.index})"
        ax.plot(range(1, len(typical.temperatures) + 1), typical.temperatures, linewidth=1.6, label=label,
                **styles[mode])
        if typical.measurements_to_hotspot:
            ax.axvline(typical.measurements_to_hotspot, linewidth=0.8, **styles[mode])
    ax.set_xlabel('measurement number')
    ax.set_ylabel('temperature [°C]')
    ax.set_title('Dead-zone experiment (paper Fig. 11): vertical lines = hotspot declared')
    ax.legend(loc='upper left')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_outputs(out: str, runs: Sequence[Run], command: str) -> str:
    """runs.tsv, deadzone.png and the page README.md in ``out``; returns the page."""
    rows = [r.row() for r in runs]
    os.makedirs(out, exist_ok=True)
    if rows:
        plot(runs, os.path.join(out, 'deadzone.png'))
    return results.write_page(out, "The paper's dead-zone experiment", 'thesis Appendix VI, Fig. 11',
                              page_body(runs), command, tables={'runs.tsv': (list(rows[0]), rows)} if rows else None)


def page_body(runs: Sequence[Run]) -> str:
    """The set-up, the table of the runs and the plot (deadzone.png) in markdown."""
    return '\n'.join(['Corridor 2 m × 12 m, heaters at x = 8.3 and 8.9 m by the upper wall, Wi-Fi only for x ≤ 1.5 m '
                      'and 10 ≤ x ≤ 11.5 m (config/link_map_corridor.yaml: both directions cut in between; '
                      'link_map_corridor_uplink.yaml: robot → cloud only), global goal manager on the cloud sending '
                      'the Z route (coverage_sweep), 50 measurements (16 s) after the hotspot, real time. Time from '
                      'the start of the run; "idle" = the MFG received no measurement or waited for a global goal '
                      '(mfg/activity), or its reports no longer reached the robot at the end (cut off). '
                      'Median (IQR, range, n).', '', table(runs), '',
                      '![temperature vs measurement number](deadzone.png)', ''])
