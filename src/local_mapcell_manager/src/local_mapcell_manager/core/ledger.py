"""What local_mapcell_manager has stored, what it still has to publish, and its hand-over in a migration
(ROS-free).

A :class:`Ledger` owns the store file, the cells (:class:`CellBook`) and the duplicate rule (:class:`Dedup`).
It receives merged measurements as :class:`Reading` s and is in one of these modes (the node switches them
from the migration hooks; an unmanaged node is *active* from the start):

- *standby* (and *frozen*): every reading is kept in a bounded buffer, nothing is stored;
- *restored* (promoted with a state, not yet active): the state replaced the store, the buffer was replayed
  over it; readings are stored and still kept in the buffer (a second promotion replays it again);
- *active*: readings are stored; the buffer is gone.

Exactly once: every instance applies the same rule to the same stream (one publisher: one order). An
instance that was frozen handed over the result of a prefix of the stream; the standby buffered a suffix
that overlaps it (it subscribed before the freeze). Each overlapping reading was already seen by the frozen
instance, so it is older than the newest one it saw or equal to one seen at that newest stamp: the rule drops
it, and the rest of the stream is applied to the same content as on the frozen instance. The result is the
one an instance that never moved would have.

The state handed over (:meth:`Ledger.state`, JSON-able; keys in the package README, "Migration state") holds
every stored measurement as column lists, the duplicate rule's bookkeeping and the measurements not yet
published; :func:`parse_state` checks it completely before anything is changed.

A standby does the bulk of a promotion ahead (:class:`Prepared`): from each replica of the active instance it
checks, files into cells and writes into a draft of its store only the measurements the replica adds, so a
promotion checks and writes only what its state adds to the newest replica (restored whole, a store of 6000+
measurements made the hand-over to the capped robot take 0.38-0.78 s at 100 ms RTT in bench_migration.sh).
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Deque, Dict, Iterable, List, Optional, Sequence, Set, Tuple

from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import HEADER, Measurement
from local_mapcell_manager.core.store import CellBook, Draft, MeasurementStore

Key = Tuple[float, float, float, float]

STORED, DUPLICATE, OUTSIDE = 'stored', 'duplicate', 'outside'


def measurement_key(time: float, x: float, y: float, temperature: float) -> Key:
    """A measurement's identity at the store's precision (cnr_maps.measurements: 6 decimals of s, 4 of m, degC)."""
    return round(time, 6), round(x, 4), round(y, 4), round(temperature, 4)


class Dedup:
    """The duplicate rule: a measurement is stored once.

    A reading older than the newest one seen (stored, or outside the grid), or equal in stamp and values to one
    seen at that newest stamp, is a duplicate (a store-and-forward receiver that crashed between delivering
    and saving its mark delivers again; a migration's standby replays what it buffered). Different readings
    with one stamp are all kept.
    """

    def __init__(self, newest_time: Optional[float] = None, keys: Iterable[Key] = ()) -> None:
        self.newest_time = newest_time
        self.keys: Set[Key] = set(keys)            # every key seen at newest_time

    @classmethod
    def of(cls, ms: Iterable[Measurement]) -> 'Dedup':
        d = cls()
        for m in ms:
            d.add(measurement_key(m.time, m.x, m.y, m.temperature))
        return d

    def is_duplicate(self, key: Key) -> bool:
        return self.newest_time is not None and (key[0] < self.newest_time or key in self.keys)

    def add(self, key: Key) -> None:
        if self.newest_time is None or key[0] > self.newest_time:
            self.newest_time, self.keys = key[0], {key}
        elif key[0] == self.newest_time:
            self.keys.add(key)


@dataclass(frozen=True)
class Reading:
    """A merged measurement as received: stamp [s], robot position [m], temperature [degC], the stamp of the pose
    it was merged with [s], yaw [rad] (published on, not stored)."""
    time: float
    x: float
    y: float
    temperature: float
    pose_time: float
    yaw: float


class _Content:
    """Stored measurements with their cells, the duplicate rule and what is not published yet."""

    def __init__(self, grid: MapcellGrid, ms: Sequence[Measurement] = (), dedup: Optional[Dedup] = None,
                 book: Optional[CellBook] = None) -> None:
        self.book = book if book is not None else CellBook(grid)   # (``ms`` added to it)
        for m in ms:
            self.book.add(m)
        self.dedup = dedup if dedup is not None else Dedup.of(ms)
        self.unpublished: Dict[int, Tuple[Measurement, float]] = {}    # number -> (measurement, yaw), in order
        self.duplicates = 0
        self.outside = 0

    def apply(self, r: Reading) -> Tuple[str, Optional[Measurement]]:
        key = measurement_key(r.time, r.x, r.y, r.temperature)
        if self.dedup.is_duplicate(key):
            return DUPLICATE, None
        self.dedup.add(key)
        m = self.book.new_measurement(r.time, r.x, r.y, r.temperature, r.pose_time)
        if m is None:
            return OUTSIDE, None
        self.book.add(m)
        self.unpublished[m.number] = (m, r.yaw)
        return STORED, m


@dataclass
class Replay:
    """What replaying the buffer did."""
    buffered: int = 0         # readings in the buffer
    stored: int = 0           # new: stored now
    known: int = 0            # already in the content (the overlap with the state handed over)
    outside: int = 0          # outside the grid
    prepared: Optional[int] = None    # restore: the state's measurements a Prepared held (None: restored whole)


class Ledger:
    """The node's data (not thread-safe: the node holds its lock).

    Args:
        grid: the mapcells.
        store: the store file; its rows are reloaded now.
        buffer_size: readings kept while buffering (the oldest are dropped beyond it).
        warn: callback for warnings (the buffer bound hit).
    """

    def __init__(self, grid: MapcellGrid, store: MeasurementStore, buffer_size: int,
                 warn: Callable[[str], None] = lambda s: None) -> None:
        if buffer_size < 1:
            raise ValueError(f'buffer_size must be >= 1, got {buffer_size}')
        self.grid = grid
        self.store = store
        self.warn = warn
        self.c = _Content(grid, store.load(grid))
        self.storing = False                       # store what is received
        self.keeping = True                        # keep what is received in the buffer
        self.buffer: Deque[Reading] = deque(maxlen=buffer_size)
        self.buffer_dropped = 0

    # ------------------------------------------------------------------ reading
    @property
    def book(self) -> CellBook:
        return self.c.book

    @property
    def count(self) -> int:
        return self.c.book.count

    @property
    def newest_time(self) -> Optional[float]:
        """The newest stamp stored (or seen outside the grid); None: nothing yet."""
        return self.c.dedup.newest_time

    @property
    def duplicates(self) -> int:
        return self.c.duplicates

    @property
    def outside(self) -> int:
        return self.c.outside

    @property
    def mode(self) -> str:
        if self.storing:
            return 'restored' if self.keeping else 'active'
        return 'buffering'

    def measurements(self, cell: Optional[int] = None) -> List[Measurement]:
        return self.c.book.measurements(cell)

    # ------------------------------------------------------------------ the stream
    def receive_many(self, rs: Sequence[Reading]) -> List[Tuple[str, Optional[Measurement]]]:
        """Readings that arrive together (a relay's batch), stored with one write and one fsync; the outcome
        of each as :meth:`receive`'s."""
        outcomes = [self.receive(r, write=False) for r in rs]
        self.store.append_many([m for _, m in outcomes if m is not None])
        return outcomes

    def receive(self, r: Reading, write: bool = True) -> Tuple[str, Optional[Measurement]]:
        """A reading arrives: kept in the buffer and/or stored, depending on the mode. Returns
        ('buffered', None) when it is only buffered, else the outcome of storing it (STORED with the
        measurement, DUPLICATE, OUTSIDE). ``write`` False: the caller appends the stored measurement to the
        store file itself."""
        if self.keeping:
            if len(self.buffer) == self.buffer.maxlen:
                if self.buffer_dropped == 0:
                    self.warn(f'standby buffer full ({self.buffer.maxlen} readings): the oldest are dropped from '
                              f'now on (they must be in the state handed over at the promotion)')
                self.buffer_dropped += 1
            self.buffer.append(r)
        if not self.storing:
            return 'buffered', None
        outcome, m = self.c.apply(r)
        if outcome == DUPLICATE:
            self.c.duplicates += 1
        elif outcome == OUTSIDE:
            self.c.outside += 1
        elif write:
            self.store.append(m)
        return outcome, m

    def pending(self) -> List[Tuple[Measurement, float]]:
        """Stored measurements not published yet (with their yaw), in order."""
        return list(self.c.unpublished.values())

    def published(self, numbers: Iterable[int]) -> None:
        for n in numbers:
            self.c.unpublished.pop(n, None)

    # ------------------------------------------------------------------ recovery
    def missing_since(self, newest: Optional[float]) -> Optional[float]:
        """At a promotion onto ``newest`` (the newest stamp of the state taken over, or of the own content; None:
        nothing stored): the stamp from which received readings may be missing, or None if the buffer reaches
        back to it (it holds a reading at or before ``newest``: nothing published since can have been missed,
        one publisher's stream arrives in order).

        A gap happens when no instance was receiving: the active one cut off on the other host (a failover
        with the last replicated state) or this one subscribed late (a fresh instance). The merger retains what
        it published (``Ledger.recover``)."""
        if self.buffer and newest is not None and self.buffer[0].time <= newest:
            return None
        return newest if newest is not None else 0.0

    def recover(self, readings: Sequence[Reading]) -> int:
        """Readings the publisher retained from before the buffer's start on, in publication order (they reach
        back to ``missing_since``), put ahead of the buffer; buffered readings they hold already (equal in
        stamp and values) are dropped from the buffer, so the promotion that follows replays the stream in its
        order through the duplicate rule. Returns how many readings were not buffered."""
        if not readings:
            return 0
        recovered = {measurement_key(r.time, r.x, r.y, r.temperature) for r in readings}
        rest = [r for r in self.buffer if measurement_key(r.time, r.x, r.y, r.temperature) not in recovered]
        added = len(readings) - (len(self.buffer) - len(rest))
        merged = list(readings) + rest
        maxlen = self.buffer.maxlen
        if len(merged) > maxlen:
            self.warn(f'standby buffer full ({maxlen} readings): the {len(merged) - maxlen} oldest recovered '
                      f'readings dropped')
            self.buffer_dropped += len(merged) - maxlen
        self.buffer = deque(merged[-maxlen:], maxlen=maxlen)
        return added

    # ------------------------------------------------------------------ migration
    def _replay(self, content: _Content) -> Tuple[Replay, List[Measurement]]:
        out, new = Replay(buffered=len(self.buffer)), []
        for r in self.buffer:
            outcome, m = content.apply(r)
            if outcome == STORED:
                out.stored += 1
                new.append(m)
            elif outcome == OUTSIDE:
                out.outside += 1
                content.outside += 1
            else:
                out.known += 1
        return out, new

    def restore(self, state: Dict[str, Any], prepared: Optional['Prepared'] = None) -> Replay:
        """Promotion with a state: the store becomes the state's measurements plus what the buffer adds (the
        file rewritten atomically), and readings are stored from now on. With ``prepared`` (this standby's
        :class:`Prepared`), only what the state adds to it is checked and written; it is used up (a refused
        state leaves it as it was, unless the store could not be written).

        Raises:
            ValueError: the state does not fit (naming the field) or the store cannot be rewritten; nothing
                changed.
        """
        h = parse_state(state, self.grid, prepared)
        try:
            if h.reused is not None:
                book, draft = prepared.book, prepared.draft
                prepared.release()                 # (its book and draft are this content's now)
                added = h.measurements[h.reused:]
                content = _Content(self.grid, added, h.dedup, book=book)
            else:
                content = _Content(self.grid, h.measurements, h.dedup)
                draft, added = None, h.measurements
            content.unpublished = {m.number: (m, yaw) for m, yaw in h.unpublished}
            content.duplicates, content.outside = h.duplicates, h.outside
            replay, new = self._replay(content)
            try:
                draft = draft if draft is not None else Draft(self.store)
                draft.append(added)
                draft.append(new)
                draft.install()
            except OSError as exc:
                raise ValueError(f'cannot rewrite the store {self.store.path}: {exc}') from None
        finally:
            if prepared is not None:
                prepared.discard()             # (unused, or released)
        self.c = content
        self.storing = True
        replay.prepared = h.reused
        return replay

    def take_over(self) -> Optional[Replay]:
        """Promotion without a state (first start, or a frozen instance promoted again): keep the own content
        and add the buffer. None if readings are stored already."""
        if self.storing:
            return None
        replay, new = self._replay(self.c)
        self.storing = True
        self.store.append_many(new)
        return replay

    def activated(self) -> Optional[Replay]:
        """The lease is granted: store from now on, no buffer any more."""
        replay = self.take_over()
        self.keeping = False
        self.buffer.clear()
        self.buffer_dropped = 0
        return replay

    def freeze(self) -> bool:
        """Frozen for a migration (or superseded): nothing stored from now on, readings buffered again (a
        rollback promotes this instance again). False if it was not storing."""
        if not self.storing:
            return False
        self.storing = False
        self.keeping = True
        self.buffer.clear()
        self.buffer_dropped = 0
        return True

    def state(self) -> Dict[str, Any]:
        """The state handed over (JSON-able; every list is a copy)."""
        ms = self.c.book.measurements()
        g = self.grid
        cols = {'measurement': [m.number for m in ms], 'time': [m.time for m in ms], 'x': [m.x for m in ms],
                'y': [m.y for m in ms], 'temperature': [m.temperature for m in ms], 'cell': [m.cell for m in ms],
                'row': [m.row for m in ms], 'col': [m.col for m in ms], 'pose_time': [m.pose_time for m in ms]}
        unpublished = list(self.c.unpublished.items())
        return {
            'grid': {'min_x': g.min_x, 'min_y': g.min_y, 'cell_size': g.cell_size, 'cols': g.cols, 'rows': g.rows},
            'measurements': cols,
            'newest': {'time': self.c.dedup.newest_time, 'keys': sorted(list(k) for k in self.c.dedup.keys)},
            'unpublished': {'measurement': [n for n, _ in unpublished], 'yaw': [y for _, (_, y) in unpublished]},
            'duplicates': self.c.duplicates,
            'outside': self.c.outside,
        }


# ---------------------------------------------------------------------- the state, checked
@dataclass
class Handover:
    measurements: List[Measurement]
    dedup: Dedup
    unpublished: List[Tuple[Measurement, float]]      # (measurement, yaw), in order
    duplicates: int
    outside: int
    reused: Optional[int] = None                     # the first measurements: a Prepared's (None: not used)


class Prepared:
    """A standby's hand-over done ahead (see the module's doc): the measurements of the newest replica it was
    given (:meth:`update`), checked, filed into cells and written into a draft of the store. Not thread-safe:
    the node serialises :meth:`update` and the :meth:`Ledger.restore` that uses it up.

    Raises (update):
        ValueError: the replica's measurements do not fit the grid (naming the field); the draft is dropped.
        OSError: the draft cannot be written; dropped.
    """

    def __init__(self, grid: MapcellGrid, store: MeasurementStore) -> None:
        self.grid = grid
        self.store = store
        self.columns: Optional[List[List[Any]]] = None     # the replica's columns the measurements came from
        self.measurements: List[Measurement] = []
        self.book = CellBook(grid)
        self.draft: Optional[Draft] = None

    def fits(self, columns: List[List[Any]]) -> bool:
        """Do ``columns`` begin with the measurements prepared? (The replicas' lists share their items: the
        comparison is mostly by identity.)"""
        n = len(self.measurements)
        return (self.columns is not None and
                all(len(c) >= n and (c is p or c[:n] == p) for c, p in zip(columns, self.columns)))

    def rest(self, columns: List[List[Any]]) -> List[Measurement]:
        """The rows of ``columns`` after the prepared ones, checked (``columns`` must fit)."""
        return _parse_rows(columns, self.grid, len(self.measurements),
                           self.measurements[-1].number if self.measurements else 0)

    def update(self, state: Any) -> int:
        """Follow a replica: prepare what it adds (everything, if it does not extend what was prepared).
        Returns the measurements added."""
        try:
            columns = _columns(state)
            if not self.fits(columns):
                self.discard()
            new = self.rest(columns)
            if self.draft is None:
                self.draft = Draft(self.store)
            self.draft.append(new)
        except (ValueError, OSError):
            self.discard()
            raise
        for m in new:
            self.book.add(m)
        self.measurements += new
        self.columns = columns
        return len(new)

    def release(self) -> None:
        """Forget what was prepared without touching it (a restore took the book and the draft)."""
        self.columns, self.measurements, self.book, self.draft = None, [], CellBook(self.grid), None

    def discard(self) -> None:
        """Drop what was prepared (the draft deleted)."""
        if self.draft is not None:
            self.draft.discard()
        self.release()


def state_newest(state: Any) -> Optional[float]:
    """The newest stamp a handed-over state holds (its ``newest.time``), or None if it has none or the state is
    malformed (:func:`parse_state` then refuses it, naming the field)."""
    try:
        t = state['newest']['time']
    except (TypeError, KeyError):
        return None
    return float(t) if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t) else None


def _fail(field: str, problem: str) -> ValueError:
    return ValueError(f'local_mapcell_manager state: {field} {problem}')


def _item(d: Any, key: str, field: str) -> Any:
    """``d[key]`` of the object ``d`` (``field`` names it in errors)."""
    if not isinstance(d, dict):
        parent = field.rpartition('.')[0] or 'the state'
        raise _fail(parent, f'must be an object, got {type(d).__name__}')
    if key not in d:
        raise _fail(field, 'is missing')
    return d[key]


def _list(v: Any, field: str) -> List[Any]:
    if not isinstance(v, list):
        raise _fail(field, f'must be a list, got {type(v).__name__}')
    return v


def _integer(v: Any, field: str, minimum: Optional[int] = None) -> int:
    if not isinstance(v, int) or isinstance(v, bool):
        raise _fail(field, f'must be an integer, got {v!r}')
    if minimum is not None and v < minimum:
        raise _fail(field, f'must be >= {minimum}, got {v}')
    return v


def _number(v: Any, field: str, finite: bool = True) -> float:
    if not isinstance(v, (int, float)) or isinstance(v, bool) or (finite and not math.isfinite(v)):
        raise _fail(field, f'must be a {"finite " if finite else ""}number, got {v!r}')
    return float(v)


GRID_KEYS = ('min_x', 'min_y', 'cell_size', 'cols', 'rows')


def _columns(state: Any) -> List[List[Any]]:
    """The state's measurement columns (in HEADER order), checked to be lists of one length."""
    cols = _item(state, 'measurements', 'measurements')
    columns = [_list(_item(cols, name, f'measurements.{name}'), f'measurements.{name}') for name in HEADER]
    for name, col in zip(HEADER, columns):
        if len(col) != len(columns[0]):
            raise _fail(f'measurements.{name}', f'has {len(col)} items, measurements.{HEADER[0]} has '
                                                f'{len(columns[0])}')
    return columns


def _parse_rows(columns: List[List[Any]], grid: MapcellGrid, start: int, last: int) -> List[Measurement]:
    """The measurements of rows ``start`` on, checked; ``last``: the number of the row before (0: none)."""
    ms: List[Measurement] = []
    for i, (number, t, x, y, temp, cell, row, col, pose_time) in enumerate(zip(*(c[start:] for c in columns)),
                                                                          start):
        last = _integer(number, f'measurements.measurement[{i}]', minimum=last + 1)    # increasing
        cell = _integer(cell, f'measurements.cell[{i}]', minimum=0)
        row, col = _integer(row, f'measurements.row[{i}]'), _integer(col, f'measurements.col[{i}]')
        if cell >= len(grid) or grid.row_col(cell) != (row, col):
            raise _fail(f'measurements.cell[{i}]', f'{cell} (row {row}, col {col}) is not a cell of the grid')
        ms.append(Measurement(last, _number(t, f'measurements.time[{i}]'), _number(x, f'measurements.x[{i}]'),
                              _number(y, f'measurements.y[{i}]'),
                              _number(temp, f'measurements.temperature[{i}]'), cell, row, col,
                              _number(pose_time, f'measurements.pose_time[{i}]')))
    return ms


def parse_state(state: Any, grid: MapcellGrid, prepared: Optional[Prepared] = None) -> Handover:
    """Check a handed-over state completely against this instance's grid; the measurements a ``prepared``
    holds (when the state's begin with them) were checked when they were prepared (``reused``).

    Raises:
        ValueError: naming the first field that is missing, of the wrong type, or inconsistent.
    """
    g = _item(state, 'grid', 'grid')
    theirs = {k: _number(_item(g, k, f'grid.{k}'), f'grid.{k}') for k in GRID_KEYS}
    ours = {k: getattr(grid, k) for k in GRID_KEYS}
    if theirs != ours:
        raise _fail('grid', f'{theirs} is not this instance\'s grid {ours}')

    columns = _columns(state)
    reused = None
    if prepared is not None and prepared.fits(columns):
        reused = len(prepared.measurements)
        ms = prepared.measurements + prepared.rest(columns)
    else:
        ms = _parse_rows(columns, grid, 0, 0)

    newest = _item(state, 'newest', 'newest')
    raw_time = _item(newest, 'time', 'newest.time')
    newest_time = None if raw_time is None else _number(raw_time, 'newest.time')
    keys: List[Key] = []
    for i, k in enumerate(_list(_item(newest, 'keys', 'newest.keys'), 'newest.keys')):
        if not isinstance(k, list) or len(k) != 4:
            raise _fail(f'newest.keys[{i}]', f'must be [time, x, y, temperature], got {k!r}')
        t, x, y, temp = (_number(v, f'newest.keys[{i}]') for v in k)
        if t != newest_time:
            raise _fail(f'newest.keys[{i}]', f'has the time {t!r}, not newest.time {newest_time!r}')
        keys.append((t, x, y, temp))
    if ms and (newest_time is None or newest_time < round(max(m.time for m in ms), 6)):
        raise _fail('newest.time', f'{newest_time!r} is older than a stored measurement')

    unpub = _item(state, 'unpublished', 'unpublished')
    numbers = _list(_item(unpub, 'measurement', 'unpublished.measurement'), 'unpublished.measurement')
    yaws = _list(_item(unpub, 'yaw', 'unpublished.yaw'), 'unpublished.yaw')
    if len(yaws) != len(numbers):
        raise _fail('unpublished.yaw', f'has {len(yaws)} items, unpublished.measurement has {len(numbers)}')
    unpublished: List[Tuple[Measurement, float]] = []
    for i, (number, yaw) in enumerate(zip(numbers, yaws)):
        number = _integer(number, f'unpublished.measurement[{i}]')
        at = bisect.bisect_left(ms, number, key=lambda m: m.number)        # (numbers increase)
        if at == len(ms) or ms[at].number != number:
            raise _fail(f'unpublished.measurement[{i}]', f'{number} is not a stored measurement')
        unpublished.append((ms[at], _number(yaw, f'unpublished.yaw[{i}]', finite=False)))

    return Handover(measurements=ms, dedup=Dedup(newest_time, keys), unpublished=unpublished,
                    duplicates=_integer(_item(state, 'duplicates', 'duplicates'), 'duplicates', minimum=0),
                    outside=_integer(_item(state, 'outside', 'outside'), 'outside', minimum=0), reused=reused)
