"""Analysis for bench_migration (ROS-free): the consumer-side downtime of a migration from a
migration_probe TSV, and the table of the results.

Two measures of a hand-over, both where the output is consumed:

- **consumer gap**: from the last output of the old instance to the first output of the
  new one. It holds the module's own output period too: a stream published once a second (mfg's activity) or
  only when input arrives (local_mapcell_manager's store output, ≈ 3 Hz) shows that gap even when nothing
  moves.
- **downtime**: from the moment the old instance closed its outputs for good (its frozen status's stamp) to the
  first output of the new one arriving at the consumer: the time during which no instance could produce output.
  The two stamps come from different hosts; on the testbed they share one clock (network namespaces of one
  kernel), so the difference is exact there. For the store (local_mapcell_manager), whose output is its input
  stored, it is the longest a measurement waited for a store across the hand-over: from its arrival on
  ``/merged_measurements`` to its arrival, stored by the new instance, on ``/mapcell_measurements`` (matched by
  header stamp; a store waiting for input is not down).

For a module whose output carries its instance (the ``cnr_instance`` connection header: local_mapcell_manager's
mapcell_measurements, mfg's activity, move_base's cmd_vel) the new instance's first output is exact; for the
global goal manager, whose only output is its service's answers, it is the first successful answer (by the time
its request was sent: the probe asks 20 times a second), and the gap is the longest between successful answers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from cnr_benchmarks.core.stats import percentile

# which output tells, on the consumer's side, that a module is working
OUTPUT_TOPIC = {
    'local_mapcell_manager': '/mapcell_measurements',
    'mfg': '/mfg/activity',
    'move_base': '/mobile_base/commands/velocity',
    'global_goal_manager': 'next_goal',
}


INPUT_TOPIC = {'local_mapcell_manager': '/merged_measurements'}     # output = this input, stored


@dataclass(frozen=True)
class ProbeRow:
    time: float
    topic: str
    instance: str
    ok: bool
    stamp: float = math.nan        # the message's header stamp (types with a header)


def read_probe(path: str, tail_bytes: int = 0) -> List[ProbeRow]:
    """The probe's rows; with ``tail_bytes`` only those in the file's last bytes (cheap on a long run)."""
    with open(path, newline='') as f:
        if tail_bytes:
            f.seek(0, 2)
            start = max(0, f.tell() - tail_bytes)
            f.seek(start)
            lines = f.read().splitlines()[1:]       # the first line is partial (or the header)
        else:
            lines = f.read().splitlines()[1:]
    rows = []
    for line in lines:
        parts = line.split('\t')
        if len(parts) in (4, 5):
            try:
                stamp = float(parts[4]) if len(parts) == 5 and parts[4] else math.nan
                rows.append(ProbeRow(float(parts[0]), parts[1], parts[2], parts[3] == '1', stamp))
            except ValueError:
                continue                             # a line being written
    return rows


def output_flowing(rows: Sequence[ProbeRow], module: str, now: float, within: float) -> bool:
    """Is the module producing output now (a row of its output topic in the last ``within`` s)? For move_base
    that means a goal is being driven: a hand-over measured then is not mixed with the wait for the next goal."""
    topic = OUTPUT_TOPIC[module]
    return any(r.topic == topic and r.ok and now - within <= r.time <= now for r in rows)


def output_period(rows: Sequence[ProbeRow], module: str, longest: float = 5.0) -> float:
    """Median time between two outputs of the module (gaps over ``longest`` s left out): the gap a consumer sees
    without any migration."""
    topic = OUTPUT_TOPIC[module]
    times = np.array([r.time for r in rows if r.topic == topic and r.ok])
    d = np.diff(times)
    d = d[d <= longest]
    return float(np.median(d)) if d.size else math.nan


def handover_gap(rows: Sequence[ProbeRow], module: str, source: str, target: str, t0: float,
                 t1: float) -> Optional[float]:
    """The consumer's downtime of one migration ordered at ``t0`` and answered at ``t1`` (wall s).

    None if it cannot be told (no output from the new instance within 10 s after ``t1``, or, for instance-tagged
    outputs, none from the old one before the switch), or, for move_base, if its goal ended in between (the gap
    then holds the wait for the next goal)."""
    topic = OUTPUT_TOPIC[module]
    window = [r for r in rows if r.topic == topic and t0 - 5.0 <= r.time <= t1 + 10.0]
    if topic == 'next_goal':
        times = [r.time for r in window if r.ok]
        if not times or times[-1] < t1:
            return None
        return float(max((b - a for a, b in zip(times, times[1:])), default=math.nan))
    old, new = f'{module}@{source}', f'{module}@{target}'
    first_new = next((r.time for r in window if r.instance == new and r.time >= t0), None)
    if first_new is None:
        return None
    last_old = max((r.time for r in window if r.instance == old and r.time <= first_new), default=None)
    if last_old is None:
        return None
    if module == 'move_base' and any(r.topic == '/move_base/result' and last_old <= r.time <= first_new
                                     for r in rows):
        return None
    return first_new - last_old


def handover_downtime(rows: Sequence[ProbeRow], module: str, source: str, target: str, t0: float,
                      t1: float) -> Optional[float]:
    """The downtime of one migration ordered at ``t0`` and answered at ``t1`` (wall s): the old instance's outputs
    closed (its ``frozen`` row) to the new instance's first output at the consumer. None if it cannot be told (the
    old instance was not frozen: a failover; no output from the new one within 10 s; move_base's goal ended in
    between)."""
    topic = OUTPUT_TOPIC[module]
    frozen = next((r.time for r in rows if r.topic == 'frozen' and r.instance == f'{module}@{source}'
                   and t0 - 1.0 <= r.time <= t1 + 1.0), None)
    if frozen is None:
        return None
    window = [r for r in rows if r.topic == topic and frozen <= r.time <= t1 + 10.0]
    if topic == 'next_goal':
        first_new = next((r.time for r in window if r.ok), None)
    else:
        first_new = next((r.time for r in window if r.instance == f'{module}@{target}'), None)
    if first_new is None:
        return None
    if module == 'move_base' and any(r.topic == '/move_base/result' and frozen <= r.time <= first_new for r in rows):
        return None
    if module in INPUT_TOPIC:
        return input_wait(rows, module, target, frozen, first_new, t1)
    return first_new - frozen


def _key(stamp: float) -> int:
    return round(stamp * 1e5)          # a stamp through float seconds and back may move by a nanosecond


def input_wait(rows: Sequence[ProbeRow], module: str, target: str, frozen: float, first_new: float,
               t1: float) -> Optional[float]:
    """The longest an input waited for its output across a hand-over: among the new instance's outputs whose
    input arrived before its first output (they waited through the hand-over; the first one itself included),
    the largest output arrival - input arrival. None without stamps (a probe file from before they were
    recorded)."""
    arrived = {_key(r.stamp): r.time for r in rows if r.topic == INPUT_TOPIC[module] and math.isfinite(r.stamp)
               and frozen - 1.0 <= r.time <= t1 + 10.0}
    waits = []
    for r in rows:
        if (r.topic == OUTPUT_TOPIC[module] and r.instance == f'{module}@{target}' and first_new <= r.time <= t1 + 10.0
                and math.isfinite(r.stamp) and _key(r.stamp) in arrived):
            t_in = arrived[_key(r.stamp)]
            if t_in <= first_new or r.time == first_new:
                waits.append(r.time - t_in)
    return max(waits) if waits else None


def stray_outputs(rows: Sequence[ProbeRow], module: str, source: str, target: str, t0: float, t1: float) -> int:
    """Outputs of the old instance received after the new one's first output (within 10 s after ``t1``): more
    than 0 means both were producing at once (never expected; messages already in flight excepted)."""
    topic = OUTPUT_TOPIC[module]
    if topic == 'next_goal':
        return 0
    window = [r for r in rows if r.topic == topic and t0 - 5.0 <= r.time <= t1 + 10.0]
    first_new = next((r.time for r in window if r.instance == f'{module}@{target}' and r.time >= t0), None)
    if first_new is None:
        return 0
    return sum(1 for r in window if r.instance == f'{module}@{source}' and r.time > first_new)


@dataclass
class Group:
    key: Tuple
    gaps: List[float]
    manager: List[float]
    outcomes: Dict[str, int]
    downtimes: List[float] = field(default_factory=list)

    HEADER = ('done', 'downtime p50', 'downtime p95', 'downtime max', 'gaps', 'gap p50', 'gap p95', 'gap max',
              'manager p50', 'manager p95')

    def row(self) -> List[str]:
        def ms(x: float) -> str:
            return '–' if not math.isfinite(x) else f'{1000 * x:.0f}'
        n_ok = self.outcomes.get('done', 0)
        return [*map(str, self.key), f'{n_ok}/{sum(self.outcomes.values())}',
                ms(percentile(self.downtimes, 50)), ms(percentile(self.downtimes, 95)),
                ms(max(self.downtimes, default=math.nan)), str(len(self.gaps)),
                ms(percentile(self.gaps, 50)), ms(percentile(self.gaps, 95)), ms(max(self.gaps, default=math.nan)),
                ms(percentile(self.manager, 50)), ms(percentile(self.manager, 95))]


def group_results(results: Sequence[Dict[str, str]], keys: Sequence[str]) -> List[Group]:
    groups: Dict[Tuple, Group] = {}
    for r in results:
        key = tuple(r[k] for k in keys)
        g = groups.setdefault(key, Group(key, [], [], {}))
        g.outcomes[r['outcome']] = g.outcomes.get(r['outcome'], 0) + 1
        if r['outcome'] == 'done':
            for value, into in ((r['consumer_gap'], g.gaps), (r['manager_downtime'], g.manager),
                                (r.get('downtime', ''), g.downtimes)):
                if value not in ('', 'nan', 'None'):
                    into.append(float(value))
    return [groups[k] for k in sorted(groups, key=lambda k: tuple(float(x) if x.replace('.', '').isdigit() else x
                                                                   for x in k))]
