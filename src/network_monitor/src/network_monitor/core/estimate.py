"""A_bw between probes (passive, no probe bytes) and R_bw = A_bw / C_bw (thesis Eq. 4-1).

Passive estimate. A probe measures A_p at time t_p. Afterwards nothing is sent; the only evidence is the
robot's own traffic, whose peak since the probe, over at most the last ``window`` seconds (P,
:meth:`BandwidthEstimator.usage_span`), proves the link carried at least that much. Usage from before the
probe is older than the probe and does not count (it once replaced a fresh 1 Mbit/s probe by the 26 Mbit/s
the link carried before its rate dropped). The estimate therefore decays from the probe value towards what is proven::

    L    = max(P, floor_fraction * A_p)                    # lower bound: proven usage, or a floor
    A(t) = L + (A_p - L) * 2 ** (-(t - t_p) / half_life)   # half of the unproven part gone per half-life
    A(t) = max(A(t), P)                                     # usage above the estimate raises it

so an old probe counts for less and less, and usage above the estimate raises it at once (the link
evidently carries it). Method is ``'probe'`` while the probe is younger than ``fresh`` seconds, then
``'passive'``; ``'none'`` (A_bw NaN) before the first successful probe. A failed probe leaves the last
good one in place.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple


def r_bw(a_bw: float, c_bw: float, c_bw_floor: float) -> float:
    """Bandwidth ratio R_bw = A_bw / C_bw (Eq. 4-1), with C_bw floored at ``c_bw_floor`` (> 0) so that an
    idle link gives a large finite ratio instead of infinity. NaN if A_bw or C_bw is unknown (NaN)."""
    if math.isnan(a_bw) or math.isnan(c_bw):
        return math.nan
    return a_bw / max(c_bw, c_bw_floor)


@dataclass
class PassiveSettings:
    fresh: float            # s a probe result is reported as method 'probe'
    window: float           # s of C_bw windows whose peak is the proven usage P
    half_life: float        # s
    floor_fraction: float   # 0..1 of the probe value the estimate never decays below


class BandwidthEstimator:
    """The last probe plus the passive decay."""

    def __init__(self, settings: PassiveSettings) -> None:
        self.settings = settings
        self.probe_value: Optional[float] = None
        self.probe_time = -math.inf

    def probed(self, now: float, bits_per_second: float) -> None:
        """A successful probe result at ``now``."""
        self.probe_value = bits_per_second
        self.probe_time = now

    def usage_span(self, now: float) -> float:
        """Seconds back from ``now`` whose usage counts for P: since the probe, at most ``window``."""
        return min(self.settings.window, max(0.0, now - self.probe_time))

    def estimate(self, now: float, peak_usage: float) -> Tuple[float, float, str]:
        """(A_bw [bit/s], age [s], method) at ``now`` given the peak usage P over :meth:`usage_span` (NaN if
        unknown)."""
        if self.probe_value is None:
            return math.nan, math.nan, 'none'
        s = self.settings
        age = max(0.0, now - self.probe_time)
        peak = 0.0 if math.isnan(peak_usage) else peak_usage
        floor = max(peak, s.floor_fraction * self.probe_value)
        value = floor + (self.probe_value - floor) * 2.0 ** (-age / s.half_life)
        value = max(value, peak)
        return value, age, ('probe' if age <= s.fresh else 'passive')
