"""Mapcells: a grid of square cells, each the thesis's sextuplet <min_x, max_x, min_y, max_y, centre_x, centre_y>.

ROS-free. The rule of the thesis (Figure 4-5): a point belongs to a cell when ``min < v <= max`` on both axes.
Cell edges are the floats ``min_x + k * cell_size`` (``min_y + k * cell_size``), k = 0..cols (rows): the same
numbers the cells report (:meth:`MapcellGrid.cell`), so a cell's ``max_x`` is exactly its right neighbour's
``min_x``. :meth:`MapcellGrid.index_of` is constant time (the transform the thesis wanted instead of its double
loop) and exact: the estimate ``ceil((v - min) / cell_size) - 1`` is corrected against those very edges, so
the lookup agrees with the rule at every boundary whatever the origin and cell size.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterator, List, Optional, Tuple

from cnr_params import ConfigError, Section

CONNECTIVITIES = (4, 8)


@dataclass(frozen=True)
class Mapcell:
    index: int
    row: int          # along y
    col: int          # along x
    min_x: float
    max_x: float
    min_y: float
    max_y: float
    center_x: float
    center_y: float

    @property
    def sextuplet(self) -> Tuple[float, float, float, float, float, float]:
        return (self.min_x, self.max_x, self.min_y, self.max_y, self.center_x, self.center_y)

    def contains(self, x: float, y: float) -> bool:
        """The thesis's rule: min < v <= max on both axes."""
        return self.min_x < x <= self.max_x and self.min_y < y <= self.max_y


def _axis_index(v: float, lo: float, size: float, n: int) -> Optional[int]:
    """k with edge(k) < v <= edge(k + 1), edge(k) = lo + k * size, or None outside (0..n-1)."""
    if not math.isfinite(v):
        return None
    estimate = (v - lo) / size
    if not estimate > -1.0 or estimate > n + 1.0:        # far outside (or overflowed)
        return None
    k = min(max(math.ceil(estimate) - 1, 0), n - 1)
    while k > 0 and v <= lo + k * size:                     # at most a step or two: rounding of the estimate
        k -= 1
    while k < n - 1 and v > lo + (k + 1) * size:
        k += 1
    return k if lo + k * size < v <= lo + (k + 1) * size else None


@dataclass(frozen=True)
class MapcellGrid:
    """``cols`` x ``rows`` cells of ``cell_size`` [m] whose lower-left corner is (min_x, min_y) [m].

    Cell ``index = row * cols + col`` (row-major, row 0 at min y, col 0 at min x).
    """

    min_x: float
    min_y: float
    cell_size: float
    cols: int
    rows: int

    @classmethod
    def from_section(cls, sec: Section) -> 'MapcellGrid':
        """Parse ``{min_x, min_y, cell_size, cols, rows}`` (errors name the field; no defaults)."""
        return cls(min_x=sec.number('min_x'), min_y=sec.number('min_y'),
                   cell_size=sec.number('cell_size', positive=True),
                   cols=sec.integer('cols', minimum=1), rows=sec.integer('rows', minimum=1))

    @classmethod
    def from_cell_states(cls, msg: Any) -> 'MapcellGrid':
        """The grid described by a cnr_msgs/CellStates message (``rows``, ``cols``, ``cell_size``, ``cells``).

        The origin is cell 0's lower-left corner; the edges are then the same floats the message's cells carry.
        """
        first = msg.cells[0]
        return cls(min_x=first.min_x, min_y=first.min_y, cell_size=msg.cell_size, cols=msg.cols, rows=msg.rows)

    def edge_x(self, col: int) -> float:
        """x [m] of the left edge of column ``col`` (``col = cols``: the grid's right edge)."""
        return self.min_x + col * self.cell_size

    def edge_y(self, row: int) -> float:
        """y [m] of the lower edge of row ``row`` (``row = rows``: the grid's upper edge)."""
        return self.min_y + row * self.cell_size

    @property
    def max_x(self) -> float:
        return self.edge_x(self.cols)

    @property
    def max_y(self) -> float:
        return self.edge_y(self.rows)

    def __len__(self) -> int:
        return self.rows * self.cols

    def cell(self, index: int) -> Mapcell:
        if not 0 <= index < len(self):
            raise IndexError(f'cell index {index} outside 0..{len(self) - 1}')
        row, col = divmod(index, self.cols)
        x0, y0 = self.edge_x(col), self.edge_y(row)
        return Mapcell(index, row, col, x0, self.edge_x(col + 1), y0, self.edge_y(row + 1),
                       x0 + 0.5 * self.cell_size, y0 + 0.5 * self.cell_size)

    def cells(self) -> Iterator[Mapcell]:
        return (self.cell(i) for i in range(len(self)))

    def index_of(self, x: float, y: float) -> Optional[int]:
        """Index of the cell containing (x, y) (min < v <= max), or None outside the grid or not finite. O(1)."""
        col = _axis_index(x, self.min_x, self.cell_size, self.cols)
        if col is None:
            return None
        row = _axis_index(y, self.min_y, self.cell_size, self.rows)
        return None if row is None else row * self.cols + col

    def row_col(self, index: int) -> Tuple[int, int]:
        """(row, col) of a cell index."""
        if not 0 <= index < len(self):
            raise IndexError(f'cell index {index} outside 0..{len(self) - 1}')
        return divmod(index, self.cols)

    def index_at(self, row: int, col: int) -> Optional[int]:
        if 0 <= row < self.rows and 0 <= col < self.cols:
            return row * self.cols + col
        return None

    def neighbours(self, index: int, connectivity: int) -> List[int]:
        """Indices of the 4- or 8-connected neighbours inside the grid."""
        if connectivity not in CONNECTIVITIES:
            raise ValueError(f'connectivity must be 4 or 8, got {connectivity}')
        row, col = self.row_col(index)
        steps = [(-1, 0), (1, 0), (0, -1), (0, 1)]
        if connectivity == 8:
            steps += [(-1, -1), (-1, 1), (1, -1), (1, 1)]
        out = []
        for dr, dc in steps:
            j = self.index_at(row + dr, col + dc)
            if j is not None:
                out.append(j)
        return out

    def chebyshev(self, a: int, b: int) -> int:
        """Distance between two cells in cells (8-connected steps)."""
        ra, ca = self.row_col(a)
        rb, cb = self.row_col(b)
        return max(abs(ra - rb), abs(ca - cb))

    def check_inside(self, bounds: Tuple[float, float, float, float], source: str, field: str = 'mapcells') -> None:
        """Raise ConfigError if the grid is not inside map bounds (x_min, y_min, x_max, y_max)."""
        x0, y0, x1, y1 = bounds
        if self.min_x < x0 or self.min_y < y0 or self.max_x > x1 or self.max_y > y1:
            raise ConfigError(source, field, f'grid [{self.min_x:g}, {self.max_x:g}] x [{self.min_y:g}, {self.max_y:g}] '
                                             f'm is outside the map [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m')
