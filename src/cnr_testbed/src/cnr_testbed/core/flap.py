"""Seeded random outage schedules for an intermittent link (ROS-free).

A schedule is a list of :class:`Outage` events, one after the other with a gap between them: a full cut (``kind``
``outage``) or a burst of random loss (``kind`` ``loss``, its ``loss`` in 0..1), in one direction (``up`` = robot ->
cloud, ``down``) or ``both``. The same seed gives the same schedule. :func:`trace_steps` turns it into the testbed's
trace steps (:class:`cnr_testbed.core.config.TraceStep`), and :func:`trace_text` into the TSV that ``testbed.sh trace
FILE`` plays::

    events = schedule(seed=7, count=20)
    open('flap.tsv', 'w').write(trace_text(events))      # testbed.sh trace flap.tsv

Defaults are the distributions of an unstable Wi-Fi link: outages 0.2-15 s, gaps 0.5-20 s, loss bursts of 30-90 %;
durations and gaps are log-uniform (many short, some long), directions and kinds uniform.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

from cnr_testbed.core.config import TraceStep

DIRECTIONS = ('both', 'up', 'down')
KINDS = ('outage', 'loss')


@dataclass(frozen=True)
class Outage:
    """One event: from ``start`` [s after the schedule began] for ``duration`` [s]."""

    start: float
    duration: float
    direction: str     # both, up (robot -> cloud), down (cloud -> robot)
    kind: str          # outage (nothing passes) or loss (each packet lost with probability ``loss``)
    loss: float = 1.0  # 0..1; 1.0 for an outage

    @property
    def end(self) -> float:
        return self.start + self.duration

    def describe(self) -> str:
        what = 'cut' if self.kind == 'outage' else f'{100 * self.loss:.0f} % loss'
        return f'{self.start:7.2f} s +{self.duration:5.2f} s {self.direction:>4} {what}'


@dataclass(frozen=True)
class FlapSettings:
    """The distributions a schedule is drawn from (s, and a fraction for loss)."""

    outage: Tuple[float, float] = (0.2, 15.0)
    gap: Tuple[float, float] = (0.5, 20.0)
    loss: Tuple[float, float] = (0.3, 0.9)
    directions: Sequence[str] = DIRECTIONS
    kinds: Sequence[str] = KINDS
    lead: float = 0.0      # quiet time before the first event

    def check(self) -> 'FlapSettings':
        for name in ('outage', 'gap', 'loss'):
            low, high = getattr(self, name)
            if not (0 < low <= high and math.isfinite(high)):
                raise ValueError(f'{name}: expected 0 < min <= max, got ({low}, {high})')
        if self.loss[1] > 1.0:
            raise ValueError(f'loss: a fraction of at most 1, got {self.loss[1]}')
        if not self.directions or set(self.directions) - set(DIRECTIONS):
            raise ValueError(f'directions: some of {", ".join(DIRECTIONS)}, got {list(self.directions)}')
        if not self.kinds or set(self.kinds) - set(KINDS):
            raise ValueError(f'kinds: some of {", ".join(KINDS)}, got {list(self.kinds)}')
        if self.lead < 0:
            raise ValueError(f'lead: must be >= 0, got {self.lead}')
        return self


def _log_uniform(rng: random.Random, bounds: Tuple[float, float]) -> float:
    low, high = bounds
    return math.exp(rng.uniform(math.log(low), math.log(high)))


def schedule(seed: int, count: int, settings: Optional[FlapSettings] = None) -> List[Outage]:
    """``count`` events drawn from ``settings`` with a generator seeded by ``seed``; the first starts after
    ``settings.lead``, each next one a gap after the previous one's end."""
    if count < 0:
        raise ValueError(f'count: must be >= 0, got {count}')
    settings = (settings or FlapSettings()).check()
    rng = random.Random(seed)
    events: List[Outage] = []
    t = settings.lead
    for i in range(count):
        if i:
            t += _log_uniform(rng, settings.gap)
        duration = _log_uniform(rng, settings.outage)
        direction = rng.choice(list(settings.directions))
        kind = rng.choice(list(settings.kinds))
        loss = 1.0 if kind == 'outage' else rng.uniform(*settings.loss)
        events.append(Outage(round(t, 3), round(duration, 3), direction, kind, round(loss, 3)))
        t = events[-1].end
    return events


def onset(event: Outage) -> Dict[str, object]:
    """The conditions that begin ``event``."""
    return {'outage': True} if event.kind == 'outage' else {'loss': event.loss}


def trace_steps(events: Sequence[Outage], clear: Optional[Dict[str, object]] = None) -> List[TraceStep]:
    """Two steps per event (its onset, then ``clear`` on the same direction at its end; default: no outage, no
    loss), in time order. Events must not overlap."""
    clear = dict(clear if clear is not None else {'outage': False, 'loss': 0.0})
    steps: List[TraceStep] = []
    last_end = -math.inf
    for e in events:
        if e.start < last_end:
            raise ValueError(f'events overlap: one starts at {e.start} s, before the previous one ends '
                             f'({last_end} s)')
        steps.append(TraceStep(e.start, e.direction, onset(e)))
        steps.append(TraceStep(e.end, e.direction, dict(clear)))
        last_end = e.end
    return steps


def trace_text(events: Sequence[Outage], clear: Optional[Dict[str, object]] = None) -> str:
    """The TSV trace (header ``time direction loss outage``) that ``testbed.sh trace FILE`` plays."""
    rows = ['# outage schedule: ' + str(len(events)) + ' events', 'time\tdirection\tloss\toutage']
    for step in trace_steps(events, clear):
        loss = step.changes.get('loss')
        outage = step.changes.get('outage')
        rows.append(f'{step.time:.3f}\t{step.direction}\t{"" if loss is None else loss}\t'
                    f'{"" if outage is None else str(bool(outage)).lower()}')
    return '\n'.join(rows) + '\n'


__all__ = ['FlapSettings', 'Outage', 'onset', 'schedule', 'trace_steps', 'trace_text']
