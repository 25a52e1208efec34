"""The split mission under a flapping link: configurations, per-run measures, the page (ROS-free).

Each run is a two-host mission report folder (``summary.json``, ``placement.tsv``, the migration instances' logs)
plus what the bench itself wrote beside it: ``schedule.tsv`` (the outage schedule it played, with the wall-clock
time each event began and ended) and ``restore.tsv`` (per outage, how long after the link returned both masters
again held each other's registrations: the longest any one discrepancy lasted, counted from the return or from
when it arose if later, and the time until the invariant held unbroken), with ``watch.tsv`` (every change of the
discrepancies, one per registration) to tell an outage the next event cut short
(:mod:`multimaster_bridge.core.restore`). This module turns a folder into a :class:`Run` and runs into the page.

Goal line (per run): 0 measurements missing, 0 duplicated, the mission completed (hotspot found), the longest
standstill with a task pending no longer than the outages it overlaps + 2 s, every restore <= 1 s, at most one
active instance of a module at any time.
"""
from __future__ import annotations

import glob
import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

from cnr_benchmarks.core.stats import percentile
from multimaster_bridge.core import restore

# configuration -> (placement, run_mission options besides --two-host --placement). The network-aware main job
# is --network-aware (which implies --migration; its decider places the patrol task's modules itself).
CONFIGS: Dict[str, Tuple[str, Tuple[str, ...]]] = {
    'monitoring_cloud': ('monitoring_cloud', ()),
    'monitoring_cloud+migration': ('monitoring_cloud', ('--migration',)),
    'paper_normal': ('paper_normal', ()),
    'paper_normal+migration': ('paper_normal', ('--migration',)),
    'move_base_cloud': ('move_base_cloud', ()),
    'move_base_cloud+migration': ('move_base_cloud', ('--migration',)),
    'network_aware': ('all_robot', ('--network-aware',)),
}
STANDSTILL_SLACK = 2.0      # s: the robot with a task pending gets a goal within (outage + this)
RESTORE_GOAL = 1.0          # s: registrations restored this long after the link returns at most
SCHEDULE_COLUMNS = ['index', 'start', 'duration', 'direction', 'kind', 'loss', 'wall_start', 'wall_end']
RESTORE_COLUMNS = ['index', 'wall_end', 'restored_after', 'lag', 'last_problems']
WATCH_COLUMNS = ['wall', 'holds', 'problems']     # watch.tsv: every change of the invariant's discrepancies

# rospy's console lines: ``[INFO] [<wall time>]: ...``, or ``[INFO] [<wall time>, <sim time>]: ...`` under sim time
_STAMP = r'\[(?:INFO|WARN|ERROR)\] \[(?P<t>\d+\.\d+)(?:, [\d.]+)?\]: '
_LOG_LINE = re.compile(_STAMP + r'(?P<id>[\w/]+@\w+): (?P<what>.*)$')
_ACTIVE = re.compile(r'active \(term (\d+)\)')
_INACTIVE = ('lease lapsed', 'frozen', 'superseded', 'dormant')
_FAILOVER = re.compile(_STAMP + r'(?P<module>\w+): .*failing over to (?P<host>\w+)')


def run_folder(scratch: str, config: str, index: int) -> str:
    return os.path.join(scratch, 'runs', f'{config}-{index:02d}')


def mission_args(config: str) -> List[str]:
    """run_mission.sh's arguments for ``config`` (without the link and the report folder)."""
    placement, extra = CONFIGS[config]
    return ['--two-host', '--placement', placement, *extra]


@dataclass(frozen=True)
class Interval:
    start: float
    end: float


def active_intervals(log_lines: Iterable[str], end_of_log: Optional[float] = None) -> Dict[str, List[Interval]]:
    """Per instance (``module@host``), the wall-clock intervals in which it was active, from its rospy log lines
    (``[INFO] [<wall time>]: mfg@cloud: active (term 3)``; ends at a lapsed lease, a freeze, supersession,
    sleep, or the log's last line — the process ended)."""
    out: Dict[str, List[Interval]] = {}
    open_at: Dict[str, float] = {}
    last = None
    for line in log_lines:
        m = _LOG_LINE.search(line.rstrip('\n'))
        if not m:
            continue
        t, inst, what = float(m.group('t')), m.group('id').lstrip('/'), m.group('what')
        last = t if last is None else max(last, t)
        if _ACTIVE.match(what):
            open_at.setdefault(inst, t)
        elif what.startswith(_INACTIVE) and inst in open_at:
            out.setdefault(inst, []).append(Interval(open_at.pop(inst), t))
    end = end_of_log if end_of_log is not None else last
    for inst, t in open_at.items():
        out.setdefault(inst, []).append(Interval(t, max(t, end if end is not None else t)))
    return out


def most_active_at_once(intervals: Dict[str, List[Interval]]) -> Dict[str, int]:
    """Per module, the most instances active at the same time (a sweep over the intervals' ends; an interval
    that ends when another begins does not overlap it)."""
    by_module: Dict[str, List[Tuple[float, int]]] = {}
    for inst, ivs in intervals.items():
        module = inst.split('@', 1)[0]
        for iv in ivs:
            by_module.setdefault(module, []).extend([(iv.start, 1), (iv.end, -1)])
    out = {}
    for module, edges in by_module.items():
        level = best = 0
        for _, step in sorted(edges, key=lambda e: (e[0], e[1])):
            level += step
            best = max(best, level)
        out[module] = best
    return out


def read_instance_logs(folder: str) -> Dict[str, List[Interval]]:
    """Active intervals of every managed instance whose log is in the report (``logs/instances/*.log``)."""
    merged: Dict[str, List[Interval]] = {}
    for path in sorted(glob.glob(os.path.join(folder, '**', 'instances', '*.log'), recursive=True)):
        with open(path, errors='replace') as f:
            for inst, ivs in active_intervals(f).items():
                merged.setdefault(inst, []).extend(ivs)
    return merged


@dataclass(frozen=True)
class Event:
    """One outage of the schedule as played: its schedule fields and the wall-clock times it began and ended."""
    index: int
    start: float
    duration: float
    direction: str
    kind: str
    loss: float
    wall_start: float
    wall_end: float


def read_tsv_rows(path: str) -> List[Dict[str, str]]:
    if not os.path.exists(path):
        return []
    with open(path) as f:
        lines = [ln.rstrip('\n').split('\t') for ln in f if ln.strip() and not ln.startswith('#')]
    return [dict(zip(lines[0], row)) for row in lines[1:]] if lines else []


def read_schedule(folder: str) -> List[Event]:
    return [Event(int(r['index']), float(r['start']), float(r['duration']), r['direction'], r['kind'],
                  float(r['loss']), float(r['wall_start']), float(r['wall_end']))
            for r in read_tsv_rows(os.path.join(folder, 'schedule.tsv'))]


def read_restores(folder: str) -> Tuple[List[Optional[float]], List[Optional[float]]]:
    """Per outage, as the bench recorded them at run time (None: not restored before the next outage or the end):
    the restore per discrepancy (``lag``; a folder written before that column gives the next measure, its upper
    bound) and the time until the invariant held unbroken (``restored_after``)."""
    rows = read_tsv_rows(os.path.join(folder, 'restore.tsv'))
    unbroken = [float(r['restored_after']) if r.get('restored_after') else None for r in rows]
    lags = [(float(r['lag']) if r['lag'] else None) if 'lag' in r else u for r, u in zip(rows, unbroken)]
    # no discrepancy at all after the return: restored by the first poll, which the unbroken time is then
    lags = [u if lag == 0.0 and u is not None else lag for lag, u in zip(lags, unbroken)]
    return lags, unbroken


def read_watch(folder: str) -> Optional[List[Tuple[float, List[str]]]]:
    """``watch.tsv``: every change of the discrepancies (wall time, one discrepancy per registration), or None
    without it (or when it names them one line per master: it cannot time them one by one)."""
    rows = read_tsv_rows(os.path.join(folder, 'watch.tsv'))
    record = [(float(r['wall']), r['problems'].split('; ') if r.get('problems') else []) for r in rows]
    if not record or any(', extra [' in p for _, wrong in record for p in wrong):
        return None
    return record


def restores_of(folder: str, events: Sequence['Event']) -> Tuple[List[Optional[float]], List[Optional[float]],
                                                                 List[bool]]:
    """Per outage: the restore per discrepancy and the unbroken restore as recorded at run time (``restore.tsv``,
    timed on every poll; None: not restored), and whether the outage was cut short: the next event began less than
    RESTORE_GOAL after the return (:func:`cut_short`), or, from ``watch.tsv`` where it names the discrepancies one
    by one, those still open when it began had arisen less than RESTORE_GOAL before (counted from the poll before
    the one that first shows them, which watch.tsv keeps beside each change; in an older file without it, from the
    change before: an overestimate, never a cut too many)."""
    lags, unbroken = read_restores(folder)
    short = cut_short(lags, events)
    record = read_watch(folder)
    if record is not None and len(lags) == len(events):
        for i, e in enumerate(events[:-1]):
            if lags[i] is None and not short[i]:
                _, open_age = restore.discrepancy_restore(record, e.wall_end, events[i + 1].wall_start)
                short[i] = open_age < RESTORE_GOAL
    return lags, unbroken, short


def cut_short(restores: Sequence[Optional[float]], events: Sequence['Event']) -> List[bool]:
    """Per outage, whether its restore went unmeasured because the next event began less than RESTORE_GOAL after
    the link returned, before the registrations were restored: such an outage can neither meet nor miss the
    bound (the next outage's restore covers both). An outage restored, or not restored with RESTORE_GOAL or more
    before the next event, is not cut short."""
    out = []
    for i, restored in enumerate(restores):
        nxt = events[i + 1] if i + 1 < len(events) else None
        out.append(restored is None and i < len(events) and nxt is not None
                   and nxt.wall_start - events[i].wall_end < RESTORE_GOAL)
    return out


def failovers(log_lines: Iterable[str]) -> List[Tuple[float, str, str]]:
    """The manager's failovers: (wall time, module, target host) of each ``<module>: ... failing over to <host>``."""
    out = []
    for line in log_lines:
        m = _FAILOVER.search(line)
        if m:
            out.append((float(m.group('t')), m.group('module'), m.group('host')))
    return out


def failover_downtimes(found: Sequence[Tuple[float, str, str]], intervals: Dict[str, List[Interval]],
                       events: Sequence['Event']) -> List[Optional[float]]:
    """Per failover, seconds from the start of the outage it followed until the module's instance on the target
    host was active (None: never)."""
    out: List[Optional[float]] = []
    for t, module, host in found:
        before = [e for e in events if e.wall_start <= t]
        cut = before[-1].wall_start if before else t
        starts = [iv.start for iv in intervals.get(f'{module}@{host}', []) if iv.start >= t]
        out.append(min(starts) - cut if starts else None)
    return out


def outage_overlap(events: Sequence[Event], start: float, end: float) -> float:
    """Seconds of ``[start, end]`` (wall clock) during which an event of the schedule was on."""
    return sum(max(0.0, min(end, e.wall_end) - max(start, e.wall_start)) for e in events)


@dataclass
class Run:
    config: str
    index: int
    folder: str
    status: Optional[int]
    completed: bool
    made: Optional[int]
    stored: Optional[int]
    missing: Optional[int]
    duplicated: Optional[int]
    outages: int
    standstill: Optional[float]                # s, the longest with a task pending
    standstill_outage: Optional[float]         # s of outage inside that standstill
    restore_median: Optional[float]            # s, per outage the longest one discrepancy lasted (the goal's)
    restore_max: Optional[float]
    not_restored: int                          # outages not restored within RESTORE_GOAL of the link's return
    failovers: int
    failover_downtimes: List[float] = field(default_factory=list)
    most_active: int = 0
    wall_time: Optional[float] = None
    restored_at_end: bool = False
    cut_short: int = 0                         # outages whose restore the next event cut short (:func:`cut_short`)
    unbroken_median: Optional[float] = None    # s, per outage until the invariant held unbroken to the next one
    unbroken_max: Optional[float] = None
    unbroken_not_restored: int = 0

    @property
    def standstill_excess(self) -> Optional[float]:
        """Standstill beyond its outages [s] (goal: <= STANDSTILL_SLACK)."""
        if self.standstill is None:
            return None
        return self.standstill - (self.standstill_outage or 0.0)

    def goal_failures(self) -> List[str]:
        """What this run misses of the goal line (empty: it meets it): :meth:`invariant_failures` and every
        restore within RESTORE_GOAL."""
        out = self.invariant_failures()
        if self.not_restored or self.restore_max is None or self.restore_max > RESTORE_GOAL:
            out.append(f'restore max {_num(self.restore_max, 2)} s, {self.not_restored} not restored')
        return out

    def invariant_failures(self) -> List[str]:
        """What this run misses of the goal line's parts that are not a time bound on the bridge: completed, 0
        missing, 0 duplicated, standstill within its outages + STANDSTILL_SLACK, at most one instance of a module
        active, and the registrations across restored after the last outage."""
        out = []
        if not self.completed:
            out.append('not completed')
        if self.missing is None or self.missing:
            out.append(f'missing {self.missing}')
        if self.duplicated is None or self.duplicated:
            out.append(f'duplicated {self.duplicated}')
        if self.standstill_excess is None or self.standstill_excess > STANDSTILL_SLACK:
            out.append('standstill ' + ('unmeasured' if self.standstill is None else
                                        f'{self.standstill:.1f} s ({self.standstill_outage or 0:.1f} s outage)'))
        if self.most_active > 1:
            out.append(f'{self.most_active} active at once')
        if not self.restored_at_end:
            out.append('registrations not restored after the last outage')
        return out

    def row(self) -> Dict:
        return dict(config=self.config, run=self.index, status=self.status, completed=self.completed,
                    made=self.made, stored=self.stored, missing=self.missing, duplicated=self.duplicated,
                    outages=self.outages, standstill=self.standstill, standstill_outage=self.standstill_outage,
                    restore_median=self.restore_median, restore_max=self.restore_max,
                    not_restored=self.not_restored, cut_short=self.cut_short,
                    unbroken_median=self.unbroken_median, unbroken_max=self.unbroken_max,
                    unbroken_not_restored=self.unbroken_not_restored, failovers=self.failovers,
                    failover_max=max(self.failover_downtimes) if self.failover_downtimes else None,
                    most_active=self.most_active, wall_time=self.wall_time,
                    goal='yes' if not self.goal_failures() else '; '.join(self.goal_failures()))


def _num(v: Optional[float], digits: int = 1) -> str:
    return '-' if v is None or (isinstance(v, float) and math.isnan(v)) else f'{v:.{digits}f}'


def standstill_of(summary: Dict, events: Sequence[Event]) -> Tuple[Optional[float], Optional[float]]:
    """The mission's longest standstill with a task pending [s] and the outage time inside it [s]
    (``summary['standstill']``: ``longest`` and the wall-clock ``longest_start``)."""
    st = summary.get('standstill') or {}
    longest = st.get('longest')
    if longest is None:
        return None, None
    start = st.get('longest_start')
    return float(longest), (outage_overlap(events, start, start + longest) if start is not None else None)


def load_run(folder: str, config: str, index: int) -> Optional[Run]:
    """A finished run (its ``summary.json`` and ``schedule.tsv`` exist), or None."""
    try:
        with open(os.path.join(folder, 'summary.json')) as f:
            s = json.load(f)
    except (OSError, ValueError):
        return None
    events = read_schedule(folder)
    try:
        with open(os.path.join(folder, 'status')) as f:
            status: Optional[int] = int(f.read().strip())
    except (OSError, ValueError):
        status = None
    check = s.get('store_check') or {}
    restores, unbroken, cut = restores_of(folder, events)
    done = [r for r in restores if r is not None]
    short = sum(cut)
    held = [r for r in unbroken if r is not None]
    standstill, standstill_outage = standstill_of(s, events)
    intervals = read_instance_logs(folder)
    found = []
    for path in sorted(glob.glob(os.path.join(folder, 'logs', '*.log'))):
        with open(path, errors='replace') as f:
            found += failovers(f)
    downtimes = failover_downtimes(sorted(found), intervals, events)
    return Run(config, index, folder, status, bool(s.get('found')),
               s.get('measurements_published_on_robot'), check.get('stored'), check.get('missing_count'),
               check.get('duplicates'), len(events), standstill, standstill_outage,
               percentile(done, 50) if done else None, max(done) if done else None,
               len(restores) - len(done) - short if restores else len(events), len(found),
               [d for d in downtimes if d is not None],
               max(most_active_at_once(intervals).values(), default=0),
               (s.get('two_host') or {}).get('wall_time_total') or s.get('wall_time'),
               bool(restores) and restores[-1] is not None, short,
               percentile(held, 50) if held else None, max(held) if held else None,
               len(unbroken) - len(held) - sum(cut_short(unbroken, events)) if unbroken else len(events))


def _sum(values: Iterable[Optional[float]]) -> Optional[float]:
    v = [x for x in values if x is not None]
    return sum(v) if v else None


def _max(values: Iterable[Optional[float]]) -> Optional[float]:
    return max((x for x in values if x is not None), default=None)


def table(runs: Sequence[Run]) -> str:
    """Markdown: per configuration, the goal line's measures over its runs."""
    lines = ['| configuration | runs (completed) | outages | made / stored | missing | duplicated | '
             'longest standstill [s] (outage in it) | restore median / max [s] (not restored; cut short) | '
             'held unbroken after median / max [s] (not restored) | failovers (longest downtime [s]) | '
             'most active at once | goal line |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for config in CONFIGS:
        rs = [r for r in runs if r.config == config]
        if not rs:
            continue
        worst = max(rs, key=lambda r: (r.standstill_excess if r.standstill_excess is not None else math.inf))
        restores = [r.restore_median for r in rs if r.restore_median is not None]
        held = [r.unbroken_median for r in rs if r.unbroken_median is not None]
        downs = [d for r in rs for d in r.failover_downtimes]
        met = sum(not r.goal_failures() for r in rs)
        lines.append(
            f'| {config} | {len(rs)} ({sum(r.completed for r in rs)}) | {sum(r.outages for r in rs)} | '
            f'{_sum(r.made for r in rs) or 0:.0f} / {_sum(r.stored for r in rs) or 0:.0f} | '
            f'{_sum(r.missing for r in rs) if all(r.missing is not None for r in rs) else "?"} | '
            f'{_sum(r.duplicated for r in rs) if all(r.duplicated is not None for r in rs) else "?"} | '
            f'{_num(worst.standstill)} ({_num(worst.standstill_outage)}) | '
            f'{_num(percentile(restores, 50), 2)} / {_num(_max(r.restore_max for r in rs), 2)} '
            f'({sum(r.not_restored for r in rs)}; {sum(r.cut_short for r in rs)}) | '
            f'{_num(percentile(held, 50), 2)} / {_num(_max(r.unbroken_max for r in rs), 2)} '
            f'({sum(r.unbroken_not_restored for r in rs)}) | '
            f'{sum(r.failovers for r in rs)} ({_num(max(downs) if downs else None, 2)}) | '
            f'{max(r.most_active for r in rs)} | {met} of {len(rs)} |')
    return '\n'.join(lines)


def page_body(runs: Sequence[Run], outages: int, seed: int) -> str:
    failing = [(r.config, r.index, r.goal_failures()) for r in runs if r.goal_failures()]
    lines = [f'Each run: one real-time two-host mission in the corridor on the testbed, with a seeded random outage '
             f'schedule of {outages} events played on the link while it runs (cnr_testbed.core.flap: cuts and loss '
             f'bursts of 30–90 %, 0.2–15 s, gaps 0.5–20 s, both directions, robot → cloud only or cloud → robot only; '
             f'run i of every configuration plays the schedule of seed {seed} + i). The mission goes on after the '
             f'hotspot until the schedule has played. Measures: measurements published on the robot against the '
             f'store at the end (the report\'s store check), the longest time the robot stood still with the '
             f'mission not done and the outage time inside it, per outage the *restore*: both masters polled at '
             f'20 Hz, each must hold the other\'s registrations as the bridges\' allow-lists permit, and every '
             f'discrepancy is timed from the link\'s return until a poll in which both masters\' answers no longer '
             f'show it (the poll\'s time: when both had answered), or from when it arose if that was '
             f'later (a registration the peer made after the return: with migration, a module\'s new instance '
             f'starting on the other host); the restore is the longest of them. Beside it, the time until the '
             f'invariant held unbroken until the next outage, which also counts registrations made after the return '
             f'(an upper bound of the restore). Then failovers of a cloud instance to the robot (migration_manager) '
             f'and the most instances of a module active at once (from the instances\' logs). An outage not yet '
             f'restored when the next event '
             f'began less than {RESTORE_GOAL:g} s after the link returned, or whose open discrepancies arose less '
             f'than {RESTORE_GOAL:g} s before the next event began, is *cut short*: it can neither meet nor miss '
             f'the bound, and the next outage\'s restore covers both.', '',
             f'Goal line per run: 0 missing, 0 duplicated, completed, standstill ≤ its outages + '
             f'{STANDSTILL_SLACK:g} s, restore ≤ {RESTORE_GOAL:g} s, at most 1 active.', '', table(runs), '']
    if failing:
        lines += ['Runs off the goal line:', '']
        lines += [f'- {c} run {i}: ' + '; '.join(f) for c, i, f in failing]
        lines.append('')
    lines.append('Every run: [runs.tsv](runs.tsv).')
    return '\n'.join(lines) + '\n'
