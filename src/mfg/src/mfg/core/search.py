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
from typing import Any, Callable, Dict, List, Optional, Sequence

from mfg.core import statecheck
from mfg.core.statecheck import state_section

OUTCOMES = ('cooler', 'hotter', 'unreachable')


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

    # -- migration state (the package README, "Migration state") -----------------------------------------
    def state(self) -> Dict[str, Any]:
        """Everything the search knows, as JSON-able values (cells are indices, temperatures degC).

        ``known``: ``[[cell, mean], ...]``; ``history``: ``[[cell, mean (NaN when unreachable), outcome], ...]``.
        The search is done when ``unchecked`` is empty.
        """
        return {'ic': self.ic, 'ic_mean': self.ic_mean, 'previous': self.previous,
                'known': [[c, m] for c, m in self.known.items()],
                'checked': list(self.checked), 'unchecked': list(self.unchecked),
                'history': [[h.cell, h.mean, h.outcome] for h in self.history],
                'ic_history': list(self.ic_history)}

    @classmethod
    def from_state(cls, neighbours: Callable[[int], Sequence[int]], state: Dict[str, Any], cells: Optional[int],
                   field: str = 'search') -> 'HotspotSearch':
        """A search that goes on exactly where :meth:`state` of another instance left off.

        Args:
            neighbours: cell -> its neighbour cells (this instance's grid).
            state: :meth:`state`.
            cells: the number of cells of the grid (every cell index is checked against it).
            field: where the state sits in the node's state (for error messages).

        Raises:
            ValueError: a key is missing or has a wrong type, or the directions are not the IC's neighbours
                (a state made on another grid); the message names ``field.key``.
        """
        sec = state_section(state, field)
        ic = statecheck.cell(sec, 'ic', cells)
        try:
            around = list(neighbours(ic))
        except (IndexError, ValueError) as exc:
            raise sec.error('ic', f'cell {ic}: {exc}') from None
        ic_mean = sec.number('ic_mean')
        previous = statecheck.cell(sec, 'previous', cells, optional=True)
        known: Dict[int, float] = {}
        for c, m in statecheck.rows(sec, 'known', 2):
            known[statecheck.check_cell(sec, 'known', c, cells)] = statecheck.number(sec, 'known', m)
        checked = statecheck.cell_list(sec, 'checked', cells)
        unchecked = statecheck.cell_list(sec, 'unchecked', cells)
        for key, directions in (('checked', checked), ('unchecked', unchecked)):
            strangers = [c for c in directions if c not in around]
            if strangers:
                raise sec.error(key, f'cells {strangers} are not neighbours of the investigation cell {ic} '
                                     f'(a state made on another grid?)')
        if set(checked) & set(unchecked):
            raise sec.error('unchecked', f'cells {sorted(set(checked) & set(unchecked))} are also checked')
        history = []
        for c, m, outcome in statecheck.rows(sec, 'history', 3):
            if outcome not in OUTCOMES:
                raise sec.error('history', f"unknown outcome {outcome!r} (expected one of: {', '.join(OUTCOMES)})")
            history.append(SearchStep(statecheck.check_cell(sec, 'history', c, cells),
                                      statecheck.number(sec, 'history', m, allow_nan=True), outcome))
        ic_history = statecheck.cell_list(sec, 'ic_history', cells)
        if not ic_history or ic_history[-1] != ic:
            raise sec.error('ic_history', f'must end with the investigation cell {ic}, got {ic_history}')
        search = cls.__new__(cls)         # not __init__: that would start a new search around ic
        search.neighbours, search.ic, search.ic_mean, search.previous = neighbours, ic, ic_mean, previous
        search.known, search.checked, search.unchecked = known, checked, unchecked
        search.history, search.ic_history = history, ic_history
        return search
