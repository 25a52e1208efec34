"""The mission's timeline (``timeline.png`` in the report, ROS-free): a network-aware run at a glance.

Four panels over the mission's sim time (s since its start): where each module ran (``placement.tsv``; a
fixed placement or one master: the summary's), the link's RTT with its outages shaded (``network_profile.tsv``:
the robot's network_monitor, ``alive`` false = no answer from the cloud; the emulator's ``link.tsv`` is not
drawn: its clock starts when the two-host launches are up, not with the mission), the measurements per second
(``measurements.tsv``), and the network-aware decisions (``decisions.tsv``) and migrations (the summary's
``migrations``) as events; the hotspot's time is marked on every panel. Reads the report folder and the summary
(a dict: the mission monitor passes the one it is about to write; the two-host mission draws it again once it
added each module's host to ``summary.json``).
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

TIMELINE = 'timeline.png'
HOST_COLORS = {'robot': '#1f77b4', 'cloud': '#ff7f0e', '-': '#bbbbbb'}


def _rows(path: str) -> List[Dict[str, str]]:
    if not os.path.isfile(path):
        return []
    with open(path, newline='') as f:
        return list(csv.DictReader(f, delimiter='\t'))


def _float(v: Optional[str]) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


@dataclass
class Timeline:
    title: str
    end: float                                                    # s, the mission's length
    hosts: Dict[str, List[Tuple[float, str, int]]] = field(default_factory=dict)   # module -> [(t, host, term)]
    rtt: List[Tuple[float, float]] = field(default_factory=list)                  # (t, RTT ms)
    down: List[Tuple[float, float]] = field(default_factory=list)                 # profile: not alive, [t0, t1)
    measurement_times: List[float] = field(default_factory=list)
    decisions: List[Tuple[float, str]] = field(default_factory=list)             # (t, label)
    migrations: List[Tuple[float, str, str]] = field(default_factory=list)       # (t, module, label)
    hotspot: Optional[float] = None


def _intervals(samples: List[Tuple[float, bool]], end: float) -> List[Tuple[float, float]]:
    """[t0, t1) spans where the flag holds, from samples (t, flag) in time order."""
    out, start = [], None
    for t, flag in samples:
        if flag and start is None:
            start = t
        elif not flag and start is not None:
            out.append((start, t))
            start = None
    if start is not None:
        out.append((start, max(end, start)))
    return out


def from_report(report_dir: str, summary: Dict) -> Timeline:
    """The timeline of the report in ``report_dir`` with its ``summary``."""
    t0 = summary.get('sim_time_start')
    end = summary.get('sim_time_total') or 0.0
    title = f"{summary.get('scenario', '')}: placement {summary.get('placement', '')}"
    tl = Timeline(title=title, end=end, hotspot=summary.get('sim_time_to_find'))
    for r in _rows(os.path.join(report_dir, 'placement.tsv')):
        tl.hosts.setdefault(r['module'], []).append((_float(r['time']), r['host'], int(_float(r['term']) or 0)))
    if not tl.hosts:        # a fixed placement: the two-host summary's hosts, else everything on the one master
        fixed = (summary.get('two_host') or {}).get('hosts') or {}
        tl.hosts = {m: [(0.0, h, 0)] for m, h in fixed.items()} if fixed else {'every module': [(0.0, 'robot', 0)]}
    profile = _rows(os.path.join(report_dir, 'network_profile.tsv'))
    tl.rtt = [(_float(r['time']), 1000.0 * _float(r['rtt'])) for r in profile]
    tl.down = _intervals([(_float(r['time']), _float(r['alive']) < 0.5) for r in profile], end)
    if t0 is not None:
        tl.measurement_times = [_float(r['time']) - t0 for r in _rows(os.path.join(report_dir, 'measurements.tsv'))]
    for r in _rows(os.path.join(report_dir, 'decisions.tsv')):
        tl.decisions.append((_float(r['time']), f"{r['event']}: {r['decision']}"))
    for m in summary.get('migrations') or []:
        tl.migrations.append((m['time'], m['module'], f"{m.get('source') or '-'}->{m['target']} {m['outcome']}"))
    return tl


def render(path: str, tl: Timeline) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(11, 7.5),
                             gridspec_kw=dict(height_ratios=[max(1.2, 0.45 * len(tl.hosts)), 1.2, 1.0, 1.2]))
    ax_h, ax_r, ax_m, ax_e = axes
    end = max([tl.end] + [t for t in tl.measurement_times if math.isfinite(t)] + [0.0])
    modules = list(tl.hosts)
    for i, module in enumerate(modules):
        changes = sorted(tl.hosts[module])
        for k, (t, host, term) in enumerate(changes):
            t1 = changes[k + 1][0] if k + 1 < len(changes) else end
            ax_h.broken_barh([(t, max(t1 - t, 0.0))], (i - 0.35, 0.7), color=HOST_COLORS.get(host, '#999999'))
            if term and t1 - t > 0.04 * max(end, 1.0):
                ax_h.text(t + 0.5, i, f'{host} t{term}', va='center', fontsize=7, color='white')
    for t, module, label in tl.migrations:
        if module in modules:
            ax_h.plot(t, modules.index(module), 'kv', markersize=6)
    ax_h.set_yticks(range(len(modules)))
    ax_h.set_yticklabels(modules, fontsize=8)
    ax_h.set_ylim(-0.6, len(modules) - 0.4)
    ax_h.invert_yaxis()
    handles = [Patch(color=c, label=h if h != '-' else 'none (migrating)') for h, c in HOST_COLORS.items()]
    if tl.migrations:
        handles.append(plt.Line2D([], [], color='k', marker='v', linestyle='', label='migration'))
    ax_h.legend(handles=handles,
                loc='lower right', bbox_to_anchor=(1.0, 1.0), fontsize=7, ncol=4, frameon=False)
    ax_h.set_title(f'{tl.title}: where each module ran', fontsize=10, loc='left')
    for a, b in tl.down:
        ax_r.axvspan(a, b, color='red', alpha=0.15, lw=0)
    if tl.rtt:
        ts, rs = zip(*tl.rtt)
        ax_r.plot(ts, rs, '.-', color='tab:green', markersize=2, linewidth=0.8)
        ax_r.set_ylabel('RTT [ms]')
        ax_r.set_title("link: RTT (the robot's network_monitor); red: no answer from the cloud (outage)", fontsize=9)
    else:
        ax_r.text(0.5, 0.5, 'one master: no link', transform=ax_r.transAxes, ha='center', va='center')
        ax_r.set_yticks([])
    if tl.measurement_times:
        n = max(1, int(math.ceil(end)))
        ax_m.hist([t for t in tl.measurement_times if math.isfinite(t)], bins=n, range=(0, n), color='tab:purple')
    ax_m.set_ylabel('meas./s')
    for t, label in tl.decisions:
        ax_e.axvline(t, color='tab:blue', linewidth=1)
        ax_e.text(t, 0.05, f' {label}', rotation=90, fontsize=7, va='bottom', ha='left', color='tab:blue')
    for t, module, label in tl.migrations:    # which module and where to: the triangles on its lane above
        ax_e.plot(t, 0.92, 'kv', markersize=5)
    ax_e.set_yticks([])
    ax_e.set_ylim(0, 1)
    ax_e.set_title('network-aware decisions (blue lines) and migrations (triangles)', fontsize=9)
    if tl.hotspot is not None:
        for ax in axes:
            ax.axvline(tl.hotspot, color='magenta', linestyle='--', linewidth=1.2)
        ax_h.text(tl.hotspot, -0.55, ' hotspot', color='magenta', fontsize=8, va='bottom')
    ax_e.set_xlabel('mission time [s, sim]')
    ax_e.set_xlim(0, max(end, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_timeline(report_dir: str, summary: Dict) -> str:
    """``timeline.png`` of the report; its path."""
    path = os.path.join(report_dir, TIMELINE)
    render(path, from_report(report_dir, summary))
    return path


def redraw_timeline(report_dir: str) -> None:
    """The timeline again from the report's ``summary.json`` (the two-host mission adds each module's host to it
    after the monitor wrote the report); nothing without a summary."""
    try:
        with open(os.path.join(report_dir, 'summary.json')) as f:
            summary = json.load(f)
    except (OSError, ValueError):
        return
    write_timeline(report_dir, summary)
