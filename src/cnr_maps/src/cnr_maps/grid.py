"""Mapcells: a grid of square cells, each the thesis's sextuplet <min_x, max_x, min_y, max_y, centre_x, centre_y>.

ROS-free. Position -> cell is constant time (the transform the thesis wanted instead of its double loop,
Figure 4-5) and keeps its boundary rule: a point belongs to a cell when min < v <= max.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator, List, Optional, Tuple

from cnr_params import ConfigError, Section


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


@dataclass(frozen=True)
class MapcellGrid:
    """``cols`` x ``rows`` cells of ``cell_size`` [m] whose lower-left corner is (min_x, min_y) [m]."""

    min_x: float
    min_y: float
    cell_size: float
    cols: int
    rows: int

    @classmethod
    def from_section(cls, sec: Section) -> 'MapcellGrid':
        return cls(min_x=sec.number('min_x'), min_y=sec.number('min_y'),
                   cell_size=sec.number('cell_size', 1.0, positive=True),
                   cols=sec.integer('cols', minimum=1), rows=sec.integer('rows', minimum=1))

    @property
    def max_x(self) -> float:
        return self.min_x + self.cols * self.cell_size

    @property
    def max_y(self) -> float:
        return self.min_y + self.rows * self.cell_size

    def __len__(self) -> int:
        return self.rows * self.cols

    def cell(self, index: int) -> Mapcell:
        if not 0 <= index < len(self):
            raise IndexError(f'cell index {index} outside 0..{len(self) - 1}')
        row, col = divmod(index, self.cols)
        x0, y0 = self.min_x + col * self.cell_size, self.min_y + row * self.cell_size
        return Mapcell(index, row, col, x0, x0 + self.cell_size, y0, y0 + self.cell_size,
                       x0 + 0.5 * self.cell_size, y0 + 0.5 * self.cell_size)

    def cells(self) -> Iterator[Mapcell]:
        return (self.cell(i) for i in range(len(self)))

    def index_of(self, x: float, y: float) -> Optional[int]:
        """Cell containing (x, y) with min < v <= max, or None outside the grid (O(1))."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        col = math.ceil((x - self.min_x) / self.cell_size) - 1
        row = math.ceil((y - self.min_y) / self.cell_size) - 1
        if 0 <= col < self.cols and 0 <= row < self.rows:
            return row * self.cols + col
        return None

    def index_at(self, row: int, col: int) -> Optional[int]:
        if 0 <= row < self.rows and 0 <= col < self.cols:
            return row * self.cols + col
        return None

    def neighbours(self, index: int, connectivity: int = 8) -> List[int]:
        """Indices of the 4- or 8-connected neighbours inside the grid."""
        row, col = divmod(index, self.cols)
        steps = [(-1, 0), (1, 0), (0, -1), (0, 1)]
        if connectivity == 8:
            steps += [(-1, -1), (-1, 1), (1, -1), (1, 1)]
        out = []
        for dr, dc in steps:
            j = self.index_at(row + dr, col + dc)
            if j is not None:
                out.append(j)
        return out

    def check_inside(self, bounds: Tuple[float, float, float, float], source: str, field: str = 'mapcells') -> None:
        """Raise ConfigError if the grid is not inside map bounds (x_min, y_min, x_max, y_max)."""
        x0, y0, x1, y1 = bounds
        if self.min_x < x0 or self.min_y < y0 or self.max_x > x1 or self.max_y > y1:
            raise ConfigError(source, field, f'grid [{self.min_x:g}, {self.max_x:g}] x [{self.min_y:g}, {self.max_y:g}] '
                                             f'm is outside the map [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m')

    def overlaps(self, other: 'MapcellGrid') -> bool:
        return (self.min_x < other.max_x and other.min_x < self.max_x and
                self.min_y < other.max_y and other.min_y < self.max_y)
