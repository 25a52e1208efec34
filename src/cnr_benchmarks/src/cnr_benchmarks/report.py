"""Writing benchmark results: TSV rows (appended as they are measured, never truncated), markdown, PNG."""
from __future__ import annotations

import os
from typing import Dict, Iterable, List, Sequence

WS = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
DEFAULT_OUT = os.path.join(WS, 'bench_results')


class TsvLog:
    """A TSV file written row by row (flushed), so an interrupted run keeps what it measured.

    An existing file is kept: a new run writes ``<name>.tsv`` after moving the old one to ``<name>.prev.tsv``.
    """

    def __init__(self, path: str, columns: Sequence[str]) -> None:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        if os.path.exists(path):
            os.replace(path, path[:-4] + '.prev.tsv')
        self.path = path
        self.columns = list(columns)
        self._f = open(path, 'w')
        self._f.write('\t'.join(self.columns) + '\n')
        self._f.flush()

    def row(self, **values) -> None:
        self._f.write('\t'.join(_fmt(values[c]) for c in self.columns) + '\n')
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def _fmt(v) -> str:
    return f'{v:.3f}' if isinstance(v, float) else str(v)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence]) -> str:
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    for r in rows:
        lines.append('| ' + ' | '.join(_cell(c) for c in r) + ' |')
    return '\n'.join(lines)


def _cell(c) -> str:
    if isinstance(c, float):
        return '–' if c != c else f'{c:.2f}'
    return str(c)


def write_text(path: str, text: str) -> None:
    tmp = f'{path}.tmp{os.getpid()}'
    with open(tmp, 'w') as f:
        f.write(text)
    os.replace(tmp, path)


def progress(msg: str) -> None:
    print(msg, flush=True)


def group(rows: List[Dict], *keys: str) -> Dict[tuple, List[Dict]]:
    out: Dict[tuple, List[Dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out
