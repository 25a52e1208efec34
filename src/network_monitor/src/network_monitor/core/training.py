"""The training set of one ⟨task, location⟩ (thesis §4.2.5, Table 4-4): a TSV file ``<dir>/<task>@<location>.tsv``.

One header line, then one row per evaluated run, tab-separated, in this order (Table 4-4's six first)::

    r_bw            R_bw = A_bw / C_bw before the task (Eq. 4-1), dimensionless, finite, > 0
    c_l             C_l, the RTT before the task [s], finite, >= 0
    decision        the migration decision that was run: offload | onload
    mission_status  completed | aborted | timed_out (evaluation.MISSION_STATUSES)
    b_task          battery used by the task [fraction of a full battery], finite, in [-1, 1]
    t_task          task time [s], finite, >= 0
    timestamp       when the task started [unix s]; ISO 8601 with a UTC offset is accepted when reading
    task, location  the ⟨task, location⟩ (the file's name)
    placement       what was placed where, e.g. ``mfg=cloud,global_goal_manager=cloud``; a module moved during
                    the task lists its hosts in turn: ``move_base=cloud>robot``
    rtt_spread      interquartile range of the RTT [s], >= 0, or nan (unknown)
    loss            ping loss [0..1] or nan
    profile_method  how A_bw was known: probe | passive
    value           Eq. 4-5's left side (evaluation.evaluation_value)
    good            1 if the mission completed and value <= V_r, else 0
    label           the placement that should have been chosen (evaluation.label_for), what the k-NN learns
    explored        1 if the decision was an exploration (not the policy's choice), else 0
    source          local | imported:<robot> (the robot whose run it was)

Floats are written with ``repr`` (shortest exact round trip), so a row read back, exported and imported is
bit-identical and decides identically.

Writing is append-only: :func:`append_rows` takes an exclusive ``flock``, writes the header only to an empty
file, writes each row as one full line, then ``fsync``\\ s; the file is never rewritten or truncated. If the
file does not end with a newline (a crash tore the last line) the new row starts on a new line, so only the
torn line is lost: reading reports it as corrupt. Reading (:func:`read_rows`) skips every corrupt line (wrong
field count, bad number, unknown decision, inconsistent label, torn last line) and returns a warning naming
the file and line, e.g. ``corridor_round_trip@corridor.tsv:17: bad r_bw 'x'``.

Shared knowledge (thesis §4.2.5, §5.4): :func:`export_set` writes a copy of a set to a new file;
:func:`import_set` adds another robot's file to a local set, validating every row, marking rows of that robot
``imported:<robot>`` (rows it had imported itself keep their origin), and skipping rows already present
(same timestamp and values, whatever the source).
"""
from __future__ import annotations

import dataclasses
import datetime
import fcntl
import math
import os
import re
from dataclasses import dataclass, fields
from typing import Callable, Dict, List, Sequence, Tuple

from cnr_params.files import fsync_directory, write_atomic
from network_monitor.core.evaluation import COMPLETED, DECISIONS, MISSION_STATUSES, label_for

PROFILE_METHODS = ('probe', 'passive')
LOCAL = 'local'
IMPORTED = 'imported:'
COLUMNS = ('r_bw', 'c_l', 'decision', 'mission_status', 'b_task', 't_task', 'timestamp', 'task', 'location',
           'placement', 'rtt_spread', 'loss', 'profile_method', 'value', 'good', 'label', 'explored', 'source')
HEADER = '\t'.join(COLUMNS)
SUFFIX = '.tsv'

_NAME = re.compile(r'^[A-Za-z0-9_.-]+$')                                # task, location, robot, module, host
_HOSTS = r'[A-Za-z0-9_.-]+(>[A-Za-z0-9_.-]+)*'                          # a host, or hosts in turn
_PLACEMENT = re.compile(rf'^([A-Za-z0-9_.-]+={_HOSTS}(,[A-Za-z0-9_.-]+={_HOSTS})*)?$')


class TrainingFileError(ValueError):
    """A file that is not a training set (wrong header), or a refused operation on one."""


def valid_name(name: str) -> bool:
    """Task, location and robot names: letters, digits, ``_ . -`` (no ``@``, ``/``, spaces)."""
    return isinstance(name, str) and bool(_NAME.match(name)) and name not in ('.', '..')


def set_path(directory: str, task: str, location: str) -> str:
    """``<directory>/<task>@<location>.tsv``."""
    for what, name in (('task', task), ('location', location)):
        if not valid_name(name):
            raise ValueError(f'bad {what} name {name!r} (letters, digits, _ . - only)')
    return os.path.join(directory, f'{task}@{location}{SUFFIX}')


@dataclass(frozen=True)
class Row:
    """One evaluated run (module docstring lists the fields, units and ranges)."""
    r_bw: float
    c_l: float
    decision: str
    mission_status: str
    b_task: float
    t_task: float
    timestamp: float
    task: str
    location: str
    placement: str
    rtt_spread: float
    loss: float
    profile_method: str
    value: float
    good: bool
    label: str
    explored: bool
    source: str

    def key(self) -> Tuple[str, ...]:
        """Identity for duplicates: every field but ``source``, as written (so NaNs compare equal)."""
        return tuple(format_fields(self)[:-1])


# ---------------------------------------------------------------- fields: parse, format, check
def _fmt_float(x: float) -> str:
    return repr(float(x))


def _fmt_bool(b: bool) -> str:
    return '1' if b else '0'


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f'{text!r}') from None


def _timestamp(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        pass
    try:
        stamp = datetime.datetime.fromisoformat(text.replace('Z', '+00:00'))
    except ValueError:
        raise ValueError(f'{text!r}') from None
    if stamp.tzinfo is None:
        raise ValueError(f'{text!r} (ISO time without a UTC offset)')
    return stamp.timestamp()


def _bool(text: str) -> bool:
    if text not in ('0', '1'):
        raise ValueError(f'{text!r} (expected 0 or 1)')
    return text == '1'


def _str(text: str) -> str:
    return text


_PARSERS: Dict[str, Callable[[str], object]] = {
    'r_bw': _float, 'c_l': _float, 'decision': _str, 'mission_status': _str, 'b_task': _float, 't_task': _float,
    'timestamp': _timestamp, 'task': _str, 'location': _str, 'placement': _str, 'rtt_spread': _float,
    'loss': _float, 'profile_method': _str, 'value': _float, 'good': _bool, 'label': _str, 'explored': _bool,
    'source': _str}
assert tuple(_PARSERS) == COLUMNS and tuple(f.name for f in fields(Row)) == COLUMNS


FLOAT_COLUMNS = tuple(c for c in COLUMNS if _PARSERS[c] in (_float, _timestamp))
BOOL_COLUMNS = tuple(c for c in COLUMNS if _PARSERS[c] is _bool)


def _number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite(x: object) -> bool:
    return _number(x) and math.isfinite(x)   # type: ignore[arg-type]


def check_row(row: Row) -> List[Tuple[str, str]]:
    """Problems with ``row`` as (field, what is wrong); empty if the row is valid."""
    p: List[Tuple[str, str]] = []
    if not (_finite(row.r_bw) and row.r_bw > 0):
        p.append(('r_bw', 'must be finite and > 0'))
    if not (_finite(row.c_l) and row.c_l >= 0):
        p.append(('c_l', 'must be finite and >= 0'))
    if row.decision not in DECISIONS:
        p.append(('decision', 'must be offload or onload'))
    if row.mission_status not in MISSION_STATUSES:
        p.append(('mission_status', f'must be one of {", ".join(MISSION_STATUSES)}'))
    if not (_finite(row.b_task) and -1.0 <= row.b_task <= 1.0):
        p.append(('b_task', 'must be finite, in [-1, 1]'))
    if not (_finite(row.t_task) and row.t_task >= 0):
        p.append(('t_task', 'must be finite and >= 0'))
    if not _finite(row.timestamp):
        p.append(('timestamp', 'must be finite'))
    for name in BOOL_COLUMNS:
        if not isinstance(getattr(row, name), bool):
            p.append((name, 'must be true or false'))
    for name in ('task', 'location'):
        if not valid_name(getattr(row, name)):
            p.append((name, 'letters, digits, _ . - only'))
    if not (isinstance(row.placement, str) and _PLACEMENT.match(row.placement)):
        p.append(('placement', 'expected module=host[,module=host...]'))
    if not (_number(row.rtt_spread) and (math.isnan(row.rtt_spread) or
                                         (math.isfinite(row.rtt_spread) and row.rtt_spread >= 0))):
        p.append(('rtt_spread', 'must be >= 0 or nan'))
    if not (_number(row.loss) and (math.isnan(row.loss) or 0.0 <= row.loss <= 1.0)):
        p.append(('loss', 'must be in [0, 1] or nan'))
    if row.profile_method not in PROFILE_METHODS:
        p.append(('profile_method', f'must be one of {", ".join(PROFILE_METHODS)}'))
    if not _finite(row.value):
        p.append(('value', 'must be finite'))
    if row.label not in DECISIONS:
        p.append(('label', 'must be offload or onload'))
    src = row.source
    if not (isinstance(src, str) and (src == LOCAL or (src.startswith(IMPORTED) and valid_name(src[len(IMPORTED):])))):
        p.append(('source', 'must be local or imported:<robot>'))
    if not p:
        if row.good and row.mission_status != COMPLETED:
            p.append(('good', f'is 1 but the mission was {row.mission_status}'))
        elif row.label != label_for(row.decision, row.good, row.mission_status):
            p.append(('label', f'inconsistent with decision {row.decision}, good {_fmt_bool(row.good)}, '
                               f'mission_status {row.mission_status}'))
    return p


def format_fields(row: Row) -> List[str]:
    """The row's TSV fields, in :data:`COLUMNS` order."""
    out = []
    for name in COLUMNS:
        v = getattr(row, name)
        out.append(_fmt_bool(v) if name in BOOL_COLUMNS else _fmt_float(v) if name in FLOAT_COLUMNS else str(v))
    return out


def format_row(row: Row) -> str:
    """One TSV line (no newline). Raises ValueError naming the first bad field."""
    problems = check_row(row)
    if problems:
        field, what = problems[0]
        raise ValueError(f'bad {field} {getattr(row, field)!r}: {what}')
    text = '\t'.join(format_fields(row))
    if '\n' in text or '\r' in text or text.count('\t') != len(COLUMNS) - 1:
        raise ValueError('a field contains a tab or newline')
    return text


def parse_line(line: str) -> Row:
    """A TSV line (no newline) -> Row. Raises ValueError with the problem, e.g. ``bad r_bw 'x'``."""
    parts = line.split('\t')
    if len(parts) != len(COLUMNS):
        raise ValueError(f'expected {len(COLUMNS)} fields, got {len(parts)}')
    values = {}
    for name, text in zip(COLUMNS, parts):
        try:
            values[name] = _PARSERS[name](text)
        except ValueError as exc:
            raise ValueError(f'bad {name} {exc}') from None
    row = Row(**values)         # type: ignore[arg-type]
    problems = check_row(row)
    if problems:
        field, what = problems[0]
        raise ValueError(f'bad {field} {parts[COLUMNS.index(field)]!r}: {what}')
    return row


# ---------------------------------------------------------------- reading and appending
def read_rows(path: str) -> Tuple[List[Row], List[str]]:
    """Every valid row of ``path`` in file order, and a warning per skipped line (``path:line: problem``).

    A missing or empty file is an empty set.

    Raises:
        TrainingFileError: the first line is not the header.
    """
    try:
        with open(path, 'rb') as stream:
            fcntl.flock(stream.fileno(), fcntl.LOCK_SH)
            data = stream.read()
    except FileNotFoundError:
        return [], []
    if not data:
        return [], []
    text = data.decode('utf-8', errors='replace')
    lines = text.split('\n')
    torn = lines.pop()                  # '' when the file ends with a newline
    if lines and lines[0].rstrip('\r') != HEADER or not lines and torn:
        raise TrainingFileError(f'{path}:1: not a training set (expected the header: {HEADER!r})')
    rows: List[Row] = []
    warnings: List[str] = []
    for number, line in enumerate(lines[1:], start=2):
        try:
            rows.append(parse_line(line.rstrip('\r')))
        except ValueError as exc:
            warnings.append(f'{path}:{number}: {exc}' if line else f'{path}:{number}: empty line')
    if torn:
        warnings.append(f'{path}:{len(lines) + 1}: torn last line (no newline; a crash while writing?)')
    return rows, warnings


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data):]


def append_rows(path: str, rows: Sequence[Row]) -> None:
    """Append ``rows`` to ``path`` (created with its header if missing), one full line per write, then fsync.

    Every row is checked before anything is written. The file is never truncated or rewritten.

    Raises:
        ValueError: a row is invalid (nothing written).
        TrainingFileError: ``path`` exists and does not start with the header.
    """
    lines = [(format_row(r) + '\n').encode('utf-8') for r in rows]
    if not lines:
        return
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    created = not os.path.exists(path)
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        size = os.fstat(fd).st_size
        header = (HEADER + '\n').encode('utf-8')
        if size == 0:
            _write_all(fd, header)
        else:
            if os.pread(fd, len(header), 0) != header:
                raise TrainingFileError(f'{path}:1: not a training set (expected the header: {HEADER!r})')
            if os.pread(fd, 1, size - 1) != b'\n':
                _write_all(fd, b'\n')       # end the torn line; it is reported as corrupt when read
        for line in lines:
            _write_all(fd, line)
        os.fsync(fd)
    finally:
        os.close(fd)
    if created:
        fsync_directory(directory)


class TrainingSet:
    """The training set of one ⟨task, location⟩ under ``directory``."""

    def __init__(self, directory: str, task: str, location: str) -> None:
        self.directory = directory
        self.task = task
        self.location = location
        self.path = set_path(directory, task, location)

    def read(self) -> Tuple[List[Row], List[str]]:
        """Valid rows and warnings (:func:`read_rows`)."""
        return read_rows(self.path)

    def append(self, *rows: Row) -> None:
        """Append rows of this ⟨task, location⟩ (:func:`append_rows`)."""
        for r in rows:
            if (r.task, r.location) != (self.task, self.location):
                raise ValueError(f'row is for {r.task}@{r.location}, not {self.task}@{self.location}')
        append_rows(self.path, rows)


# ---------------------------------------------------------------- shared knowledge: export and import
def export_set(source: str, destination: str) -> List[str]:
    """Write the valid rows of the set ``source`` to a new file ``destination`` (replaced atomically if it
    exists); returns the warnings of reading ``source``. Refuses to overwrite ``source`` itself."""
    if os.path.exists(destination) and os.path.exists(source) and os.path.samefile(source, destination):
        raise TrainingFileError(f'{destination}: refusing to export a training set onto itself')
    rows, warnings = read_rows(source)
    directory = os.path.dirname(os.path.abspath(destination))
    os.makedirs(directory, exist_ok=True)
    write_atomic(destination, HEADER + '\n' + ''.join(format_row(r) + '\n' for r in rows), durable=True)
    return warnings


@dataclass
class ImportResult:
    added: int              # rows appended to the local set
    duplicates: int         # rows already present (same timestamp and values)
    skipped: int            # valid rows of another ⟨task, location⟩
    warnings: List[str]     # corrupt lines of the foreign file, rows of another ⟨task, location⟩


def import_set(local: TrainingSet, foreign: str, robot: str) -> ImportResult:
    """Add the rows of ``foreign`` (another robot's exported set) to ``local``.

    Rows with source ``local`` become ``imported:<robot>``; rows the other robot had imported keep their
    origin. Corrupt lines and rows of another ⟨task, location⟩ are skipped with a warning; rows whose
    timestamp and values equal a row already in the local set (or earlier in the file) are skipped.
    """
    if not valid_name(robot):
        raise ValueError(f'bad robot name {robot!r} (letters, digits, _ . - only)')
    rows, warnings = read_rows(foreign)
    existing, _ = local.read()
    seen = {r.key() for r in existing}
    new: List[Row] = []
    duplicates = skipped = 0
    for r in rows:
        if (r.task, r.location) != (local.task, local.location):
            skipped += 1
            warnings.append(f'{foreign}: a row of {r.task}@{r.location} skipped (importing into '
                            f'{local.task}@{local.location})')
            continue
        if r.key() in seen:
            duplicates += 1
            continue
        seen.add(r.key())
        source = f'{IMPORTED}{robot}' if r.source == LOCAL else r.source
        new.append(dataclasses.replace(r, source=source))
    local.append(*new)
    return ImportResult(added=len(new), duplicates=duplicates, skipped=skipped, warnings=warnings)
