"""Pairs each measurement with the pose whose timestamp is closest to it (thesis Figures 4-9, 4-10).

ROS-free. Poses may arrive out of order; they are kept sorted by stamp (bisect). A measurement is
decided only once a pose *after* it has arrived (so the nearer of its two neighbours is known) or once it
is older than ``max_wait``; it is merged with the nearest pose if that is within ``tolerance``, otherwise
counted and dropped — never paired with a pose farther away than the tolerance.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Generic, List, Optional, Tuple, TypeVar

P = TypeVar('P')
M = TypeVar('M')


@dataclass
class Merged(Generic[M, P]):
    measurement_stamp: float
    measurement: M
    pose_stamp: float
    pose: P

    @property
    def difference(self) -> float:
        return abs(self.measurement_stamp - self.pose_stamp)


@dataclass
class MergerStats:
    merged: int = 0
    dropped_no_pose: int = 0       # nothing within the tolerance
    late: int = 0                  # merged or dropped after waiting max_wait
    out_of_order_poses: int = 0


class NearestMerger(Generic[M, P]):
    """Nearest-timestamp merger.

    Args:
        tolerance: maximum |t_measurement - t_pose| [s].
        max_wait: how long a measurement may wait for a later pose [s].
        pose_horizon: poses older than the newest minus this are forgotten [s].
    """

    def __init__(self, tolerance: float = 0.1, max_wait: float = 0.5, pose_horizon: float = 10.0) -> None:
        self.tolerance = tolerance
        self.max_wait = max_wait
        self.pose_horizon = pose_horizon
        self._pose_t: List[float] = []
        self._poses: List[P] = []
        self._pending: List[Tuple[float, int, M]] = []
        self._seq = 0
        self.stats = MergerStats()

    # -- input ---------------------------------------------------------------------------------
    def add_pose(self, stamp: float, pose: P) -> None:
        i = bisect.bisect_right(self._pose_t, stamp)
        if i < len(self._pose_t):
            self.stats.out_of_order_poses += 1
        self._pose_t.insert(i, stamp)
        self._poses.insert(i, pose)
        cut = bisect.bisect_left(self._pose_t, self._pose_t[-1] - self.pose_horizon)
        if cut:
            del self._pose_t[:cut]
            del self._poses[:cut]

    def add_measurement(self, stamp: float, measurement: M) -> None:
        self._seq += 1
        keys = [(e[0], e[1]) for e in self._pending]
        self._pending.insert(bisect.bisect_right(keys, (stamp, self._seq)), (stamp, self._seq, measurement))

    # -- output --------------------------------------------------------------------------------
    def nearest(self, stamp: float) -> Optional[int]:
        """Index of the pose closest in time to ``stamp`` (None without poses)."""
        if not self._pose_t:
            return None
        i = bisect.bisect_left(self._pose_t, stamp)
        candidates = [j for j in (i - 1, i) if 0 <= j < len(self._pose_t)]
        return min(candidates, key=lambda j: abs(self._pose_t[j] - stamp))

    def process(self, now: float) -> Tuple[List[Merged], List[Tuple[float, M]]]:
        """Decide every measurement that can be decided at time ``now`` [s].

        Returns:
            (merged pairs, dropped (stamp, measurement)) in measurement-stamp order.
        """
        merged, dropped, keep = [], [], []
        newest_pose = self._pose_t[-1] if self._pose_t else None
        for stamp, seq, m in self._pending:
            later_pose = newest_pose is not None and newest_pose >= stamp
            timed_out = now - stamp > self.max_wait
            if not (later_pose or timed_out):
                keep.append((stamp, seq, m))
                continue
            if timed_out and not later_pose:
                self.stats.late += 1
            j = self.nearest(stamp)
            if j is not None and abs(self._pose_t[j] - stamp) <= self.tolerance:
                merged.append(Merged(stamp, m, self._pose_t[j], self._poses[j]))
                self.stats.merged += 1
            else:
                dropped.append((stamp, m))
                self.stats.dropped_no_pose += 1
        self._pending = keep
        return merged, dropped

    @property
    def pending(self) -> int:
        return len(self._pending)

