"""The measurement TSV format (ROS-free): one merged measurement per line, the thesis's tab-separated columns.

    measurement  time  x  y  temperature  cell  row  col  pose_time

``measurement`` is the running number (from 1), ``time`` the measurement stamp [s], ``x``/``y`` the robot
position [m], ``temperature`` [degC], ``cell``/``row``/``col`` the mapcell (see :mod:`cnr_maps.grid`; -1 when
not in a cell), ``pose_time`` the stamp of the pose it was merged with [s]. Written by local_mapcell_manager's
store and by the mission report; read back by both.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Sequence

HEADER = ['measurement', 'time', 'x', 'y', 'temperature', 'cell', 'row', 'col', 'pose_time']
HEADER_LINE = '\t'.join(HEADER) + '\n'


@dataclass
class Measurement:
    number: int
    time: float
    x: float
    y: float
    temperature: float
    cell: int
    row: int
    col: int
    pose_time: float


def format_row(m: Measurement) -> str:
    """One line (with its newline)."""
    return (f'{m.number}\t{m.time:.6f}\t{m.x:.4f}\t{m.y:.4f}\t{m.temperature:.4f}\t{m.cell}\t{m.row}\t{m.col}\t'
            f'{m.pose_time:.6f}\n')


def parse_row(line: str) -> Measurement:
    """A line (without its newline) back to a measurement.

    Raises:
        ValueError: wrong number of fields or a field that is not a number.
    """
    p = line.split('\t')
    if len(p) != len(HEADER):
        raise ValueError(f'{len(p)} fields, expected {len(HEADER)}')
    return Measurement(int(p[0]), float(p[1]), float(p[2]), float(p[3]), float(p[4]), int(p[5]), int(p[6]),
                       int(p[7]), float(p[8]))


def is_header(line: str) -> bool:
    return line.rstrip('\n') == HEADER_LINE.rstrip('\n')


def write_tsv(path: str, rows: Sequence[Measurement]) -> None:
    """Write a whole file: header and rows."""
    with open(path, 'w') as f:
        f.write(HEADER_LINE)
        f.writelines(format_row(r) for r in rows)


def read_tsv(path: str) -> List[Measurement]:
    """Read a whole file written by :func:`write_tsv`.

    Raises:
        ValueError: naming the file (and line) when the header or a row is wrong.
    """
    out = []
    with open(path) as f:
        header = f.readline()
        if not is_header(header):
            raise ValueError(f'{path}: unexpected header {header.rstrip()!r}')
        for no, line in enumerate(f, 2):
            try:
                out.append(parse_row(line.rstrip('\n')))
            except ValueError as exc:
                raise ValueError(f'{path}:{no}: {exc}') from None
    return out
