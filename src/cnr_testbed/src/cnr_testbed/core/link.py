"""One direction of the emulated link: rate limit with a bounded queue, loss, delay and jitter (ROS-free).

A packet offered at time ``now`` first waits for the transmitter (token bucket of ``rate`` with no burst
beyond one packet: serialisation at the configured rate; at most ``queue`` packets wait, tail drop), is then
lost with probability ``loss`` (or always during an ``outage``), and is released ``delay`` +/- jitter later.
Jitter never reorders packets unless ``reorder`` is set (netem's behaviour with a rate). Deterministic for
tests with an injected random generator.
"""
from __future__ import annotations

import heapq
import math
import random
from dataclasses import dataclass, asdict, fields
from typing import Any, Dict, List, Optional, Tuple


@dataclass
class Conditions:
    """Link conditions of one direction.

    Attributes:
        delay: one-way delay [ms] (>= 0).
        jitter: standard deviation of the delay [ms] (>= 0; normal, clipped at 0).
        loss: packet loss probability [0..1].
        rate: rate limit [Mbit/s] (0 = unlimited).
        queue: packets that may wait for the transmitter (>= 1).
        outage: drop everything (100 % loss).
        reorder: let jitter reorder packets.
    """

    delay: float
    jitter: float
    loss: float
    rate: float
    queue: int
    outage: bool
    reorder: bool

    def validate(self, where: str = 'conditions') -> 'Conditions':
        check_changes(asdict(self), where)
        return self

    def updated(self, **changes: Any) -> 'Conditions':
        check_changes(changes)
        d = asdict(self)
        d.update(changes)
        return Conditions(**d).validate()


def check_changes(changes: Dict[str, Any], where: str = 'conditions') -> None:
    """Raise ValueError naming the first unknown condition or bad value in ``changes`` (a partial mapping)."""
    known = [f.name for f in fields(Conditions)]
    unknown = set(changes) - set(known)
    if unknown:
        raise ValueError(f'unknown condition(s): {", ".join(sorted(unknown))} (known: {", ".join(sorted(known))})')
    for name, v in changes.items():
        if name in ('delay', 'jitter', 'rate'):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v < 0:
                raise ValueError(f'{where}.{name}: must be a finite number >= 0, got {v!r}')
        elif name == 'loss':
            if not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
                raise ValueError(f'{where}.loss: must be in [0, 1], got {v!r}')
        elif name == 'queue':
            if not isinstance(v, int) or v < 1:
                raise ValueError(f'{where}.queue: must be an integer >= 1, got {v!r}')


@dataclass
class Counters:
    offered: int = 0
    delivered: int = 0
    dropped_queue: int = 0
    dropped_loss: int = 0
    bytes_delivered: int = 0


class LinkDirection:
    """Scheduler of one direction.

    Args:
        conditions: initial conditions.
        rng: random generator (loss, jitter).
    """

    def __init__(self, conditions: Conditions, rng: Optional[random.Random] = None) -> None:
        self.conditions = conditions.validate()
        self.rng = rng or random.Random()
        self.counters = Counters()
        self._heap: List[Tuple[float, int, bytes]] = []
        self._seq = 0
        self._tx_free = 0.0             # time the transmitter finishes the packets accepted so far
        self._tx_done: List[float] = []  # departure times of packets still waiting/transmitting (queue length)
        self._last_release = 0.0

    def set(self, conditions: Conditions) -> None:
        self.conditions = conditions.validate()

    def offer(self, packet: bytes, now: float) -> bool:
        """A packet enters the link at ``now`` [s]; False if it was dropped."""
        c = self.conditions
        self.counters.offered += 1
        if c.rate > 0:
            while self._tx_done and self._tx_done[0] <= now:
                heapq.heappop(self._tx_done)
            if len(self._tx_done) >= c.queue:
                self.counters.dropped_queue += 1
                return False
            start = max(now, self._tx_free)
            depart = start + len(packet) * 8 / (c.rate * 1e6)
            self._tx_free = depart
            heapq.heappush(self._tx_done, depart)
        else:
            depart = now
        if c.outage or (c.loss > 0 and self.rng.random() < c.loss):
            self.counters.dropped_loss += 1
            return False
        delay = c.delay / 1000.0
        if c.jitter > 0:
            delay = max(0.0, delay + self.rng.gauss(0.0, c.jitter / 1000.0))
        release = depart + delay
        if not c.reorder:
            release = max(release, self._last_release)
            self._last_release = release
        self._seq += 1
        heapq.heappush(self._heap, (release, self._seq, packet))
        return True

    def next_due(self) -> Optional[float]:
        return self._heap[0][0] if self._heap else None

    def due(self, now: float) -> List[bytes]:
        """Packets whose release time has come, in release order."""
        out = []
        while self._heap and self._heap[0][0] <= now:
            _, _, p = heapq.heappop(self._heap)
            out.append(p)
            self.counters.delivered += 1
            self.counters.bytes_delivered += len(p)
        return out

    @property
    def in_flight(self) -> int:
        return len(self._heap)

    def status(self) -> Dict[str, Any]:
        return dict(conditions=asdict(self.conditions), counters=asdict(self.counters), in_flight=self.in_flight)
