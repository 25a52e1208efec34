"""Accuracy and cost of network_monitor's profile against the link emulator's settings (ROS-free).

One :class:`Sample` per repetition of one grid cell (link RTT and rate set on the testbed); the cell's
summary compares it with the setting:

* RTT error [ms] = measured median RTT - (set RTT + baseline), the baseline being the RTT measured with no
  delay and no rate limit (ROS publish/echo path and emulator), reported separately;
* delay error [ms] = measured - (set RTT + the RTT measured at 0 ms and the same rate): the RTT error without
  the rate's serialisation of the ping and pong segments (about 2 x 120 bytes: 1.9 ms at 1 Mbit/s), which
  belongs to the link's real RTT but not to the delay set on the emulator;
* A_bw error [%] = 100 * (probe A_bw / set rate - 1);
* passive error [%] = 100 * (passive estimate / set rate - 1);
* probe cost: bytes on the emulated link in both directions during the probe, and the caller's seconds for
  ``~profile_now`` with a probe.

Targets: RTT within +/-2 ms, A_bw within +/-10 %, passive within +/-20 %.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

RTT_TARGET_MS = 2.0
A_BW_TARGET_PCT = 10.0
PASSIVE_TARGET_PCT = 20.0


@dataclass
class Sample:
    """One repetition in one cell. NaN where not measured (e.g. no passive phase on an unshaped link)."""
    set_rtt_ms: float
    set_rate_mbit: float          # 0 = unshaped
    rep: int
    rtt_ms: float                 # the profile's median RTT over its window
    rtt_spread_ms: float          # the profile's interquartile range
    probe_ok: int                 # 1 if ~profile_now's probe succeeded
    a_bw_mbit: float              # the probe's A_bw
    probe_s: float                # ~profile_now with a probe, the caller's wall time
    probe_iperf_bytes: int        # bytes iperf3 reports sent (profile.probe_bytes difference)
    probe_link_up_bytes: int      # bytes the emulator delivered robot -> cloud during the call
    probe_link_down_bytes: int    # and cloud -> robot
    load_mbit: float              # background traffic offered during the passive phase
    passive_mbit: float           # the profile's A_bw at passive_age_s after the probe
    passive_age_s: float
    passive_method: str
    usage_mbit: float             # the profile's C_bw then (the monitor's own view of the load)

    @classmethod
    def columns(cls) -> List[str]:
        return [f.name for f in fields(cls)]

    @classmethod
    def from_row(cls, row: Dict[str, str]) -> 'Sample':
        """A sample from a TSV row (strings)."""
        values = {}
        for f in fields(cls):
            text = row[f.name]
            values[f.name] = int(text) if f.type in ('int', int) else (text if f.type in ('str', str) else float(text))
        return cls(**values)

    @property
    def probe_link_bytes(self) -> int:
        return self.probe_link_up_bytes + self.probe_link_down_bytes


def rtt_error_ms(measured_ms: float, set_ms: float, baseline_ms: float) -> float:
    return measured_ms - (set_ms + baseline_ms)


def pct_error(measured: float, setting: float) -> float:
    return 100.0 * (measured / setting - 1.0) if setting > 0 else math.nan


@dataclass
class Spread:
    """Mean, min and max of the finite values (NaN and n = 0 if none)."""
    mean: float
    lo: float
    hi: float
    n: int

    @classmethod
    def of(cls, values: Iterable[float]) -> 'Spread':
        xs = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
        if not xs:
            return cls(math.nan, math.nan, math.nan, 0)
        return cls(sum(xs) / len(xs), min(xs), max(xs), len(xs))

    def within(self, bound: float) -> Optional[bool]:
        """Every value within +/-bound (None if there is none)."""
        return None if self.n == 0 else (abs(self.lo) <= bound and abs(self.hi) <= bound)

    def text(self, fmt: str = '.1f', signed: bool = False) -> str:
        """``mean`` or ``mean [min, max]`` when several values differ; '–' for none."""
        if self.n == 0:
            return '–'
        f = ('+' if signed else '') + fmt
        if self.n == 1 or self.lo == self.hi:
            return format(self.mean, f)
        return f'{format(self.mean, f)} [{format(self.lo, f)}, {format(self.hi, f)}]'


@dataclass
class CellSummary:
    set_rtt_ms: float
    set_rate_mbit: float
    reps: int
    rtt_ms: Spread
    rtt_error_ms: Spread
    delay_error_ms: Spread
    a_bw_mbit: Spread
    a_bw_error_pct: Spread
    probe_failures: int
    passive_mbit: Spread
    passive_error_pct: Spread
    passive_age_s: Spread
    usage_mbit: Spread
    probe_mb: Spread              # on the link, both directions
    probe_iperf_mb: Spread
    probe_s: Spread

    def met(self) -> Dict[str, Optional[bool]]:
        """Per target: every repetition within it (None if not measured, e.g. no rate set). 'delay' is the RTT
        target applied to the delay error."""
        shaped = self.set_rate_mbit > 0
        a_bw = self.a_bw_error_pct.within(A_BW_TARGET_PCT) if shaped else None
        if shaped and self.probe_failures:
            a_bw = False
        return {'rtt': self.rtt_error_ms.within(RTT_TARGET_MS), 'delay': self.delay_error_ms.within(RTT_TARGET_MS),
                'a_bw': a_bw,
                'passive': self.passive_error_pct.within(PASSIVE_TARGET_PCT) if shaped else None}


def baseline_rtt_ms(samples: Sequence[Sample], rate_mbit: float = 0.0) -> float:
    """Median RTT of the samples with no delay at ``rate_mbit`` (0: unshaped, the baseline; NaN if none)."""
    xs = sorted(s.rtt_ms for s in samples
                if s.set_rtt_ms == 0 and s.set_rate_mbit == rate_mbit and math.isfinite(s.rtt_ms))
    if not xs:
        return math.nan
    mid = len(xs) // 2
    return xs[mid] if len(xs) % 2 else (xs[mid - 1] + xs[mid]) / 2.0


def summarize_cells(samples: Sequence[Sample], baseline_ms: float) -> List[CellSummary]:
    """One summary per (set RTT, set rate), in the order the cells first appear."""
    cells: Dict[Tuple[float, float], List[Sample]] = {}
    for s in samples:
        cells.setdefault((s.set_rtt_ms, s.set_rate_mbit), []).append(s)
    out = []
    for (rtt, rate), group in cells.items():
        ok = [s for s in group if s.probe_ok]
        at_rate = baseline_rtt_ms(samples, rate)
        out.append(CellSummary(
            set_rtt_ms=rtt, set_rate_mbit=rate, reps=len(group),
            rtt_ms=Spread.of(s.rtt_ms for s in group),
            rtt_error_ms=Spread.of(rtt_error_ms(s.rtt_ms, rtt, baseline_ms) for s in group),
            delay_error_ms=Spread.of(rtt_error_ms(s.rtt_ms, rtt, at_rate) for s in group),
            a_bw_mbit=Spread.of(s.a_bw_mbit for s in ok),
            a_bw_error_pct=Spread.of(pct_error(s.a_bw_mbit, rate) for s in ok),
            probe_failures=len(group) - len(ok),
            passive_mbit=Spread.of(s.passive_mbit for s in group),
            passive_error_pct=Spread.of(pct_error(s.passive_mbit, rate) for s in group),
            passive_age_s=Spread.of(s.passive_age_s for s in group),
            usage_mbit=Spread.of(s.usage_mbit for s in group),
            probe_mb=Spread.of(s.probe_link_bytes / 1e6 for s in ok),
            probe_iperf_mb=Spread.of(s.probe_iperf_bytes / 1e6 for s in ok),
            probe_s=Spread.of(s.probe_s for s in ok)))
    return out


TABLE_HEADER = ['set RTT (ms)', 'set rate (Mbit/s)', 'RTT (ms)', 'RTT error (ms)', 'delay error (ms)', 'A_bw (Mbit/s)',
                'A_bw error (%)', 'passive (Mbit/s)', 'passive error (%)', 'probe (MB on link)',
                'probe (s)', 'targets met']


def _flag(value: Optional[bool]) -> str:
    return '–' if value is None else ('yes' if value else 'NO')


def table_rows(cells: Sequence[CellSummary]) -> List[List[str]]:
    """Markdown table cells, one row per grid cell ('mean [min, max]' over the repetitions)."""
    rows = []
    for c in cells:
        met = c.met()
        a_bw = c.a_bw_mbit.text('.2f') + (f' ({c.probe_failures} failed)' if c.probe_failures else '')
        rows.append([f'{c.set_rtt_ms:g}', f'{c.set_rate_mbit:g}' if c.set_rate_mbit > 0 else 'unshaped',
                     c.rtt_ms.text('.2f'), c.rtt_error_ms.text('.2f', signed=True),
                     c.delay_error_ms.text('.2f', signed=True), a_bw,
                     c.a_bw_error_pct.text('.1f', signed=True), c.passive_mbit.text('.2f'),
                     c.passive_error_pct.text('.1f', signed=True), c.probe_mb.text('.2f'), c.probe_s.text('.2f'),
                     f"RTT {_flag(met['rtt'])}, A_bw {_flag(met['a_bw'])}, passive {_flag(met['passive'])}"])
    return rows


def totals(cells: Sequence[CellSummary]) -> Dict[str, Tuple[int, int]]:
    """Per target: (cells that met it, cells where it applies)."""
    out = {}
    for key in ('rtt', 'delay', 'a_bw', 'passive'):
        flags = [c.met()[key] for c in cells]
        out[key] = (sum(1 for f in flags if f), sum(1 for f in flags if f is not None))
    return out
