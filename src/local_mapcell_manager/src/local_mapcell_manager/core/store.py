"""Per-cell monitoring state and the append-only measurement store (ROS-free).

The store is a TSV file in the format of :mod:`cnr_maps.measurements` (the thesis's tab-separated columns),
one merged measurement per line, flushed and fsync'ed per line. On start the file is read back to rebuild
every cell's state, so a restart loses nothing. A truncated last line (a crash while writing) is skipped with
a warning and never truncated further: new lines start on a fresh line. The only rewrite (a migration's
hand-over) is atomic: a :class:`Draft` (a temporary file in the store's directory, written ahead, e.g. by a
standby from the replicas it receives) is fsync'ed and renamed over the store.
"""
from __future__ import annotations

import contextlib
import math
import os
import re
import stat
import tempfile
from dataclasses import dataclass, field
from typing import Callable, List, Optional, Sequence

from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import HEADER_LINE, Measurement, format_row, is_header, parse_row
from cnr_params.files import fsync_directory


@dataclass
class CellState:
    """Running statistics (Welford) and the visit record of one cell."""

    last_visit: float = 0.0          # stamp of the latest measurement in the cell (timestamp method)
    visit_count: int = 0             # entries into the cell
    n: int = 0
    mean: float = math.nan
    m2: float = 0.0
    min: float = math.nan
    max: float = math.nan
    measurements: List[Measurement] = field(default_factory=list)

    def add(self, m: Measurement) -> None:
        self.measurements.append(m)
        self.n += 1
        if self.n == 1:
            self.mean, self.m2, self.min, self.max = m.temperature, 0.0, m.temperature, m.temperature
        else:
            delta = m.temperature - self.mean
            self.mean += delta / self.n
            self.m2 += delta * (m.temperature - self.mean)
            self.min, self.max = min(self.min, m.temperature), max(self.max, m.temperature)
        self.last_visit = max(self.last_visit, m.time)

    @property
    def std(self) -> float:
        return math.sqrt(self.m2 / (self.n - 1)) if self.n > 1 else math.nan


class CellBook:
    """All cells' states; counts a visit each time consecutive measurements enter a different cell."""

    def __init__(self, grid: MapcellGrid) -> None:
        self.grid = grid
        self.states = [CellState() for _ in range(len(grid))]
        self.current: Optional[int] = None
        self.count = 0

    def new_measurement(self, time: float, x: float, y: float, temperature: float,
                        pose_time: float) -> Optional[Measurement]:
        """The next numbered measurement with its cell assigned, or None outside the grid."""
        cell = self.grid.index_of(x, y)
        if cell is None:
            return None
        row, col = self.grid.row_col(cell)
        return Measurement(self.count + 1, time, x, y, temperature, cell, row, col, pose_time)

    def add(self, m: Measurement) -> None:
        if m.cell != self.current:
            self.states[m.cell].visit_count += 1
            self.current = m.cell
        self.states[m.cell].add(m)
        self.count = max(self.count, m.number)

    def measurements(self, cell: Optional[int] = None) -> List[Measurement]:
        if cell is not None:
            return list(self.states[cell].measurements)
        return sorted((m for s in self.states for m in s.measurements), key=lambda m: m.number)


class MeasurementStore:
    """Append-only TSV file of measurements.

    Args:
        path: the file (created with a header if missing; directories too).
        warn: callback for problems met while reading it back.
    """

    def __init__(self, path: str, warn: Callable[[str], None] = lambda s: None) -> None:
        self.path = path
        self.warn = warn
        os.makedirs(os.path.dirname(os.path.abspath(path)) or '.', exist_ok=True)
        self._needs_newline = False
        if not os.path.exists(path) or os.path.getsize(path) == 0:
            with open(path, 'w') as f:
                f.write(HEADER_LINE)
                f.flush()
                os.fsync(f.fileno())
        else:
            with open(path, 'rb') as f:
                f.seek(-1, os.SEEK_END)
                self._needs_newline = f.read(1) != b'\n'

    def load(self, grid: MapcellGrid) -> List[Measurement]:
        """Every complete, valid line of the file (in file order)."""
        out = []
        with open(self.path, 'r', errors='replace') as f:
            lines = f.read().split('\n')
        complete = lines[:-1]            # the text after the last newline is an unfinished line
        if lines[-1]:
            self.warn(f'{self.path}: ignoring an incomplete last line (interrupted write): {lines[-1][:60]!r}')
        for no, line in enumerate(complete, 1):
            if not line or is_header(line):
                continue
            try:
                m = parse_row(line)
                if not 0 <= m.cell < len(grid) or grid.row_col(m.cell) != (m.row, m.col):
                    raise ValueError(f'cell {m.cell} (row {m.row}, col {m.col}) is not a cell of the grid')
            except ValueError as exc:
                self.warn(f'{self.path}:{no}: ignoring a malformed line ({exc})')
                continue
            out.append(m)
        return out

    def append(self, m: Measurement) -> None:
        self.append_many([m])

    def append_many(self, ms: Sequence[Measurement]) -> None:
        """Append rows with one write and one fsync."""
        if not ms:
            return
        with open(self.path, 'a') as f:
            if self._needs_newline:
                f.write('\n')
                self._needs_newline = False
            f.write(''.join(format_row(m) for m in ms))
            f.flush()
            os.fsync(f.fileno())

    def replace(self, ms: Sequence[Measurement]) -> None:
        """Rewrite the whole file with exactly these rows, atomically (a :class:`Draft` installed): a crash leaves
        the old file or the new one, never a truncated one.

        Raises:
            OSError: the file could not be written (the old file is then unchanged).
        """
        draft = Draft(self)
        draft.append(ms)
        draft.install()

    def remove_stale_drafts(self) -> List[str]:
        """Delete the drafts of this store left by processes that no longer run (a crash before installing or
        discarding one); returns their paths."""
        directory = os.path.dirname(os.path.abspath(self.path))
        pattern = re.compile(re.escape(os.path.basename(self.path)) + r'\.draft-(\d+)-.*\.tmp$')
        removed = []
        for name in os.listdir(directory):
            m = pattern.match(name)
            if m and not os.path.exists(f'/proc/{m.group(1)}'):
                with contextlib.suppress(OSError):
                    os.unlink(os.path.join(directory, name))
                    removed.append(os.path.join(directory, name))
        return removed


class Draft:
    """The store's next content, written ahead into a temporary file next to it (``<store>.draft-<pid>-*.tmp``)
    and installed over it atomically: rows appended without fsync (cheap while a standby follows the replicas),
    everything fsync'ed once at :meth:`install`.

    Raises (all methods):
        OSError: the file could not be written; a failed draft is discarded (the store unchanged).
    """

    def __init__(self, store: MeasurementStore) -> None:
        self.store = store
        directory = os.path.dirname(os.path.abspath(store.path))
        fd, self.path = tempfile.mkstemp(prefix=f'{os.path.basename(store.path)}.draft-{os.getpid()}-',
                                         suffix='.tmp', dir=directory)
        self.file = os.fdopen(fd, 'w')
        try:
            self.file.write(HEADER_LINE)
        except BaseException:
            self.discard()
            raise

    def append(self, ms: Sequence[Measurement]) -> None:
        try:
            self.file.write(''.join(format_row(m) for m in ms))
        except BaseException:
            self.discard()
            raise

    def install(self) -> None:
        """The draft becomes the store (the old file's permissions kept); the draft is used up."""
        path = self.store.path
        directory = os.path.dirname(os.path.abspath(path))
        try:
            self.file.flush()
            os.fsync(self.file.fileno())
            self.file.close()
            with contextlib.suppress(OSError):     # keep the old file's permissions (mkstemp makes it 0600)
                os.chmod(self.path, stat.S_IMODE(os.stat(path).st_mode))
            os.replace(self.path, path)
        except BaseException:
            self.discard()
            raise
        fsync_directory(directory)                 # the rename itself survives a crash
        self.store._needs_newline = False

    def discard(self) -> None:
        with contextlib.suppress(OSError):
            self.file.close()
        with contextlib.suppress(OSError):
            os.unlink(self.path)
