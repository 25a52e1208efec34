"""Mid-task re-decision with hysteresis and a migration budget (the thesis's future work, §4.2.3, §6.3).

The thesis fixed the placement for a whole task, because migrating on every change of the network costs more
than it saves (§4.2.3: "migrations are only allowed x amount of times"). A :class:`ReDecider` is fed the
decisions made during the task (each a wanted placement and a confidence, e.g. the k-NN's vote fraction) and
switches only when

* the other placement has been wanted, with confidence >= ``margin``, in every update for at least ``dwell``
  seconds (any update wanting the current placement, or with less confidence, restarts the wait) — or it is
  *clearly* better: wanted with confidence >= ``clear_margin`` (e.g. 1.0: all k neighbours) in every update for
  ``clear_dwell`` seconds (e.g. 0.5 s: two profiles at 2 Hz), so a link that collapses is acted on within a
  second while a marginal change waits out the long dwell, and
* the migration budget allows it: at most ``max_migrations`` migrations in any ``window`` seconds (migrations
  made elsewhere, e.g. the one before the task, are counted through :meth:`ReDecider.migrated`).

A want that outlasts an exhausted budget is acted on as soon as the budget frees. With ``max_migrations: 1``
and ``window: 30`` a link oscillating around the decision boundary causes at most one migration per 30 s;
with ``dwell`` longer than the oscillation's half period, none. Pure: every call takes ``now`` [s, monotonic].
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Deque, Optional

from network_monitor.core.evaluation import DECISIONS


@dataclass(frozen=True)
class ReDecisionSettings:
    margin: float           # 0.5 < margin <= 1: confidence the other placement must be wanted with
    dwell: float            # s (>= 0) it must be wanted before a switch
    max_migrations: int     # >= 0 migrations per window (0: never switch mid-task)
    window: float           # s (> 0)
    clear_margin: Optional[float] = None    # margin <= clear_margin <= 1: a clearly better placement (None: no
    clear_dwell: float = 0.0                # such tier) switches after clear_dwell s (>= 0) instead of dwell


class ReDecider:
    """The current placement of one task's modules, re-decided as decisions arrive.

    Args:
        settings: margin, dwell, budget.
        placement: the placement at the start (offload | onload).
    """

    def __init__(self, settings: ReDecisionSettings, placement: str) -> None:
        if placement not in DECISIONS:
            raise ValueError(f'unknown placement {placement!r}')
        self.settings = settings
        self.placement = placement
        self.wanted_since: Optional[float] = None   # when the other placement began to be wanted
        self.clear_since: Optional[float] = None    # ... with at least clear_margin
        self.waited = 0.0                           # s the last switch was wanted for (the dwell it met)
        self._migrations: Deque[float] = deque()
        self._last: Optional[float] = None

    def _clock(self, now: float) -> None:
        if self._last is not None and now < self._last:
            raise ValueError(f'time went backwards: {now} < {self._last}')
        self._last = now
        while self._migrations and self._migrations[0] <= now - self.settings.window:
            self._migrations.popleft()

    def migrated(self, now: float) -> None:
        """Count a migration made at ``now`` outside this re-decider (e.g. before the task) in the budget."""
        self._clock(now)
        self._migrations.append(now)

    def budget(self, now: float) -> int:
        """Migrations still allowed at ``now`` within the window."""
        self._clock(now)
        return max(0, self.settings.max_migrations - len(self._migrations))

    def update(self, now: float, wanted: str, confidence: float) -> Optional[str]:
        """One decision at ``now``: ``wanted`` placement with ``confidence`` (0..1).

        Returns:
            the new placement if the modules should migrate now (the switch is recorded), else None.
        """
        if wanted not in DECISIONS:
            raise ValueError(f'unknown placement {wanted!r}')
        self._clock(now)
        s = self.settings
        if wanted == self.placement or confidence < s.margin:
            self.wanted_since = self.clear_since = None
            return None
        if self.wanted_since is None:
            self.wanted_since = now
        if s.clear_margin is not None and confidence >= s.clear_margin:
            self.clear_since = now if self.clear_since is None else self.clear_since
        else:
            self.clear_since = None
        by_dwell = now - self.wanted_since >= s.dwell
        by_clear = self.clear_since is not None and now - self.clear_since >= s.clear_dwell
        if not (by_dwell or by_clear) or self.budget(now) <= 0:
            return None
        self.waited = now - (self.wanted_since if by_dwell else self.clear_since)
        self.placement = wanted
        self.wanted_since = self.clear_since = None
        self._migrations.append(now)
        return wanted
