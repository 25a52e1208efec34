"""The merger's bounded memory of what it published (ROS-free).

A store that was cut off (its active instance on the cloud during an outage) or not yet subscribed (a fresh
instance still starting) misses merged measurements; the merger, which never moves off the robot, keeps the
newest ones so that the store promoted next can ask for those after its newest (``GetRecentMeasurements``).
Kept in publication order (the order every store applies its duplicate rule in), bounded by count and by
age (stamps, i.e. sim time); what is evicted is counted.
"""
from __future__ import annotations

import itertools
from collections import deque
from typing import Deque, Generic, List, Optional, Tuple, TypeVar

T = TypeVar('T')


class Retention(Generic[T]):
    """Published items with their stamps [s], in publication order: at most ``max_count``, and none stamped
    more than ``max_age`` seconds before the newest stamp."""

    def __init__(self, max_count: int, max_age: float) -> None:
        if max_count < 1:
            raise ValueError(f'max_count must be >= 1, got {max_count}')
        if not max_age > 0:
            raise ValueError(f'max_age must be > 0, got {max_age}')
        self.max_count = max_count
        self.max_age = max_age
        self._items: Deque[Tuple[float, T]] = deque()
        self._newest: Optional[float] = None
        self.evicted = 0

    def __len__(self) -> int:
        return len(self._items)

    @property
    def oldest(self) -> float:
        """The stamp of the oldest retained item (0.0: none)."""
        return min((s for s, _ in self._items), default=0.0)

    def add(self, stamp: float, item: T) -> None:
        self._items.append((stamp, item))
        self._newest = stamp if self._newest is None else max(self._newest, stamp)
        while len(self._items) > self.max_count or self._items[0][0] < self._newest - self.max_age:
            self._items.popleft()
            self.evicted += 1

    def since(self, stamp: float) -> List[Tuple[float, T]]:
        """The retained items from the first one stamped at or after ``stamp`` on, in publication order (a
        later one stamped earlier, published out of order, is included: the consumer's duplicate rule drops
        it as it did live)."""
        first = next((i for i, (s, _) in enumerate(self._items) if s >= stamp), len(self._items))
        return list(itertools.islice(self._items, first, None))
