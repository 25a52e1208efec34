"""The hotspot search of thesis §4.1.5 (Figure 4-8) as a state machine (ROS-free).

The search starts in the cell where the abnormal value was found: it becomes the current investigation
cell (IC); the cell visited before is a checked direction; every other neighbour (8- or 4-connected) is an
unchecked direction. The robot measures unchecked neighbours one by one: a cooler one becomes checked; a
hotter one becomes the new IC, the old IC becomes checked and the new IC's other neighbours become
unchecked. When no unchecked direction is left, every neighbour is cooler: the IC is the hotspot. A
neighbour that cannot be reached is marked checked and the search goes on.

One improvement over the thesis: a neighbour already measured during this search is not driven to
again; its known average decides at once (the thesis re-marks all of them unchecked).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence


@dataclass
class SearchStep:
    """What happened on a report (for logs)."""

    cell: int
    mean: float
    outcome: str          # 'cooler', 'hotter', 'unreachable'


@dataclass
class HotspotSearch:
    """Search state.

    Args:
        neighbours: cell -> its neighbour cells (inside the grid).
        ic: the cell where the abnormal value was found.
        ic_mean: its average temperature [degC].
        previous: the cell visited before (a checked direction), if any.
        known: averages already measured (cell -> degC), e.g. the previous cell's.
    """

    neighbours: Callable[[int], Sequence[int]]
    ic: int
    ic_mean: float
    previous: Optional[int] = None
    known: Dict[int, float] = field(default_factory=dict)
    checked: List[int] = field(default_factory=list)
    unchecked: List[int] = field(default_factory=list)
    history: List[SearchStep] = field(default_factory=list)
    ic_history: List[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.known[self.ic] = self.ic_mean
        self._set_ic(self.ic, self.ic_mean, self.previous)

    def _set_ic(self, ic: int, mean: float, previous: Optional[int]) -> None:
        self.ic, self.ic_mean = ic, mean
        self.ic_history.append(ic)
        self.checked = [previous] if previous is not None and previous in self.neighbours(ic) else []
        self.unchecked = [c for c in self.neighbours(ic) if c not in self.checked]
        self._settle_known()

    def _settle_known(self) -> None:
        """Decide unchecked cells whose average is already known."""
        for c in list(self.unchecked):
            if c in self.known and not self.known[c] > self.ic_mean:
                self.unchecked.remove(c)
                self.checked.append(c)
        hotter = [c for c in self.unchecked if c in self.known and self.known[c] > self.ic_mean]
        if hotter:
            best = max(hotter, key=lambda c: self.known[c])
            self.history.append(SearchStep(best, self.known[best], 'hotter'))
            self._set_ic(best, self.known[best], self.ic)

    @property
    def done(self) -> bool:
        return not self.unchecked

    @property
    def hotspot(self) -> Optional[int]:
        return self.ic if self.done else None

    def next_target(self, cost: Optional[Callable[[int], float]] = None) -> Optional[int]:
        """The unchecked direction to measure next (the cheapest by ``cost``, else the first)."""
        if not self.unchecked:
            return None
        return min(self.unchecked, key=cost) if cost else self.unchecked[0]

    def report(self, cell: int, mean: float) -> SearchStep:
        """The measured average of an unchecked neighbour [degC] (NaN = could not be measured)."""
        if cell not in self.unchecked:
            raise ValueError(f'cell {cell} is not an unchecked direction of IC {self.ic}')
        if math.isnan(mean):
            return self.unreachable(cell)
        self.known[cell] = mean
        if mean > self.ic_mean:
            step = SearchStep(cell, mean, 'hotter')
            self.history.append(step)
            self._set_ic(cell, mean, self.ic)
        else:
            step = SearchStep(cell, mean, 'cooler')
            self.history.append(step)
            self.unchecked.remove(cell)
            self.checked.append(cell)
        return step

    def unreachable(self, cell: int) -> SearchStep:
        self.unchecked.remove(cell)
        self.checked.append(cell)
        step = SearchStep(cell, math.nan, 'unreachable')
        self.history.append(step)
        return step
