"""How long the measurement feedback goal could not act (ROS-free): the paper's dead-zone figure.

The MFG is *idle* while it either receives no measurement (its input is cut off, e.g. it runs on the cloud
and the robot is in a dead zone) or waits for the global goal manager's answer. The tracker keeps the
longest input gap (an open gap counts up to ``now``), the total time waited for goals, and the longest of
both; times are the node's clock (sim time) in seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Optional

from mfg.core.statecheck import state_section


@dataclass
class ActivityReport:
    measurements: int
    longest_input_gap: float      # s, longest time between two received measurements (or since the last one)
    goal_waits: int
    goal_wait_total: float        # s waited for the global goal manager
    goal_wait_longest: float      # s
    longest_idle: float           # s, max of the two above


class ActivityTracker:
    def __init__(self) -> None:
        self.measurements = 0
        self._last_input: Optional[float] = None
        self._longest_gap = 0.0
        self.goal_waits = 0
        self._wait_total = 0.0
        self._wait_longest = 0.0

    def input(self, now: float) -> None:
        """A measurement arrived at ``now``."""
        if self._last_input is not None:
            self._longest_gap = max(self._longest_gap, now - self._last_input)
        self._last_input = now
        self.measurements += 1

    def waited(self, seconds: float) -> None:
        """The MFG waited ``seconds`` for a global goal (answered or fallen back)."""
        self.goal_waits += 1
        self._wait_total += seconds
        self._wait_longest = max(self._wait_longest, seconds)

    def report(self, now: float) -> ActivityReport:
        gap = self._longest_gap
        if self._last_input is not None:
            gap = max(gap, now - self._last_input)
        return ActivityReport(self.measurements, gap, self.goal_waits, self._wait_total, self._wait_longest,
                              max(gap, self._wait_longest))

    # -- migration state (the package README, "Migration state") -----------------------------------------
    def state(self) -> Dict[str, Any]:
        """The counters (times in s of the node's clock; ``last_input`` null before the first measurement)."""
        return {'measurements': self.measurements, 'last_input': self._last_input, 'longest_gap': self._longest_gap,
                'goal_waits': self.goal_waits, 'wait_total': self._wait_total, 'wait_longest': self._wait_longest}

    def restore(self, state: Dict[str, Any], field: str = 'activity') -> None:
        """Take over :meth:`state` of another instance (ValueError naming ``field.key`` if it does not fit)."""
        sec = state_section(state, field)
        values = (sec.integer('measurements', minimum=0),
                  None if sec.raw('last_input') is None else sec.number('last_input'),
                  sec.number('longest_gap', nonnegative=True), sec.integer('goal_waits', minimum=0),
                  sec.number('wait_total', nonnegative=True), sec.number('wait_longest', nonnegative=True))
        (self.measurements, self._last_input, self._longest_gap, self.goal_waits, self._wait_total,
         self._wait_longest) = values
