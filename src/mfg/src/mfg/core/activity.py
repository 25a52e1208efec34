"""How long the measurement feedback goal could not act (ROS-free): the paper's dead-zone figure.

The MFG is *idle* while it either receives no measurement (its input is cut off, e.g. it runs on the cloud
and the robot is in a dead zone) or waits for the global goal manager's answer. The tracker keeps the
longest input gap (an open gap counts up to ``now``), the total time waited for goals, and the longest of
both; times are the node's clock (sim time) in seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional


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
