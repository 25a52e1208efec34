"""C_bw: bytes per second on one interface in short windows (the thesis ran ``ifstat -i wlan0 0.1 1``).

:class:`RateSampler` is fed cumulative (rx, tx) byte counters with their sample times, from any reader
(``psutil.net_io_counters(pernic=True)`` in the node, a fake in tests). Every pair of consecutive samples
about ``min_window`` or more apart gives one window rate in bit/s (rx + tx: a Wi-Fi link is one shared medium,
and ifstat reports both directions). A counter that goes backwards (interface reset, wrap) or a missing
interface restarts the baseline; :meth:`gap` does the same on purpose, e.g. so an active probe's own traffic
is never counted as the robot's usage.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Callable, Deque, Optional, Tuple

Counters = Tuple[int, int]                 # cumulative (rx_bytes, tx_bytes)
CounterReader = Callable[[str], Optional[Counters]]


def sysfs_reader(root: str = '/sys/class/net') -> CounterReader:
    """A reader of ``<root>/<iface>/statistics/{rx,tx}_bytes`` (None if the interface is gone)."""
    def read(iface: str) -> Optional[Counters]:
        try:
            with open(f'{root}/{iface}/statistics/rx_bytes') as rx, open(f'{root}/{iface}/statistics/tx_bytes') as tx:
                return int(rx.read()), int(tx.read())
        except (OSError, ValueError):
            return None
    return read


def psutil_reader(psutil_module) -> CounterReader:
    """A reader over ``psutil.net_io_counters(pernic=True)`` (pass the module; None if the interface is gone)."""
    def read(iface: str) -> Optional[Counters]:
        counters = psutil_module.net_io_counters(pernic=True).get(iface)
        return None if counters is None else (counters.bytes_recv, counters.bytes_sent)
    return read


JITTER = 0.9   # a window may be this fraction of min_window short (sampling timer jitter)


class RateSampler:
    """Window rates of one interface's byte counters.

    Args:
        min_window: shortest window in seconds (0.1 s like ifstat); closer samples (below 0.9 of it, for timer jitter) are merged into the next.
        history: seconds of window rates kept for :meth:`mean` and :meth:`peak`.
    """

    def __init__(self, min_window: float, history: float) -> None:
        if not min_window > 0 or not history > 0:
            raise ValueError('min_window and history must be > 0')
        self.min_window = min_window
        self.history = history
        self._base: Optional[Tuple[float, int]] = None          # (time, rx + tx bytes)
        self._rates: Deque[Tuple[float, float]] = deque()         # (window end, bit/s)

    def gap(self) -> None:
        """Forget the baseline: the traffic until the next sample is not counted."""
        self._base = None

    def add(self, now: float, counters: Optional[Counters]) -> Optional[float]:
        """One counter sample; returns the completed window's rate in bit/s, if one completed."""
        if counters is None:
            self._base = None
            return None
        total = int(counters[0]) + int(counters[1])
        if self._base is None or total < self._base[1] or now <= self._base[0]:
            self._base = (now, total)
            return None
        dt = now - self._base[0]
        if dt < JITTER * self.min_window:
            return None
        rate = 8.0 * (total - self._base[1]) / dt
        self._base = (now, total)
        self._rates.append((now, rate))
        self._prune(now)
        return rate

    def _prune(self, now: float) -> None:
        while self._rates and self._rates[0][0] < now - self.history:
            self._rates.popleft()

    def last(self) -> float:
        """The newest window's rate in bit/s (NaN if none)."""
        return self._rates[-1][1] if self._rates else math.nan

    def last_end(self) -> float:
        """When the newest window ended (-inf if none)."""
        return self._rates[-1][0] if self._rates else -math.inf

    def mean(self, now: float, span: float) -> float:
        """Mean rate of the windows ending in ``[now - span, now]`` (NaN if none)."""
        rates = [r for t, r in self._rates if t >= now - span]
        return sum(rates) / len(rates) if rates else math.nan

    def peak(self, now: float, span: float) -> float:
        """Highest window rate ending in ``[now - span, now]`` (NaN if none)."""
        rates = [r for t, r in self._rates if t >= now - span]
        return max(rates) if rates else math.nan
