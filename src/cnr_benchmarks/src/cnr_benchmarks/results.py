"""An experiment's results: its page, tables and figures in ``docs/results/<experiment>/``.

The page is ``README.md``, headed by the title with the thesis reference and one table row saying when, on which
commit, on which machine and by which command it was measured::

    # <Title> (<thesis reference>)

    | measured | commit | machine | command |
    |---|---|---|---|
    | 2026-11-28 | <short hash>+dirty | AMD EPYC, 2 cores, Debian GNU/Linux 12 (bookworm) | `launch_scripts/bench_rtt.sh` |

TSVs and PNGs stand beside it; a re-run replaces them. Raw logs and per-run scratch go to the git-ignored
``bench_results/<experiment>/`` (:func:`scratch_dir`). No ROS imports.
"""
from __future__ import annotations

import datetime
import io
import os
import platform
import shlex
import subprocess
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Tuple

from cnr_params.files import write_atomic, write_json

WS = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
PAGE = 'README.md'


def results_dir(experiment: str, ws: str = WS) -> str:
    """``docs/results/<experiment>``: the experiment's page, tables and figures (tracked)."""
    return os.path.join(ws, 'docs', 'results', experiment)


def scratch_dir(experiment: str, ws: str = WS) -> str:
    """``bench_results/<experiment>``: raw logs and per-run scratch (git-ignored)."""
    return os.path.join(ws, 'bench_results', experiment)


@dataclass(frozen=True)
class Provenance:
    """When, on what and by which command an experiment was measured (the page's header row)."""
    measured: str
    commit: str
    machine: str
    command: str


def git_commit(ws: str = WS) -> str:
    """``git rev-parse --short HEAD`` of ``ws``, with ``+dirty`` when the tree has changes; ``unknown`` outside git."""
    try:
        head = subprocess.run(['git', '-C', ws, 'rev-parse', '--short', 'HEAD'], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return 'unknown'
        status = subprocess.run(['git', '-C', ws, 'status', '--porcelain', '--untracked-files=no'],
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return 'unknown'
    return head.stdout.strip() + ('+dirty' if status.returncode != 0 or status.stdout.strip() else '')


def machine(cpuinfo: str = '/proc/cpuinfo') -> str:
    """CPU model, cores and operating system, e.g. ``Intel(R) Xeon(R) CPU, 2 cores, Debian GNU/Linux 12 (bookworm)``."""
    model = platform.processor() or platform.machine()
    try:
        with open(cpuinfo) as f:
            for line in f:
                if line.startswith('model name'):
                    model = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        system = platform.freedesktop_os_release().get('PRETTY_NAME', '')
    except OSError:
        system = ''
    return f'{model}, {os.cpu_count()} cores, {system or platform.system() + " " + platform.release()}'


def command_line(prog: str, argv: Sequence[str]) -> str:
    """The command as typed: the script's name and its arguments."""
    return ' '.join([prog] + [shlex.quote(a) for a in argv])


def provenance(command: str, ws: str = WS, today: Optional[datetime.date] = None) -> Provenance:
    return Provenance((today or datetime.date.today()).isoformat(), git_commit(ws), machine(), command)


def header(title: str, reference: str, prov: Provenance) -> str:
    """The page's title line and its measured / commit / machine / command table."""
    return (f'# {title} ({reference})\n\n| measured | commit | machine | command |\n|---|---|---|---|\n'
            f'| {prov.measured} | {prov.commit} | {prov.machine} | `{prov.command}` |\n')


def write_page(out_dir: str, title: str, reference: str, body: str, command: str,
               figures: Optional[Mapping[str, Any]] = None,
               tables: Optional[Mapping[str, Tuple[Sequence[str], Sequence[Any]]]] = None, ws: str = WS) -> str:
    """``<out_dir>/README.md``: :func:`header` and ``body``, replacing the page of an earlier run; beside it
    ``figures`` (file name -> matplotlib figure, :func:`write_figure`) and ``tables`` (file name -> (columns,
    rows), each row a sequence or a dict by column, :func:`write_tsv`). Returns the page."""
    os.makedirs(out_dir, exist_ok=True)
    for name, fig in (figures or {}).items():
        write_figure(fig, os.path.join(out_dir, name))
    for name, (columns, rows) in (tables or {}).items():
        write_tsv(os.path.join(out_dir, name), columns,
                  [[r.get(c) for c in columns] if isinstance(r, Mapping) else r for r in rows])
    text = header(title, reference, provenance(command, ws)) + '\n' + body.rstrip('\n') + '\n'
    write_atomic(os.path.join(out_dir, PAGE), text)
    return text


def write_figure(fig: Any, path: str, dpi: int = 110) -> str:
    """A matplotlib figure as PNG at ``path`` (atomically), closed afterwards; returns ``path``."""
    import matplotlib.pyplot as plt
    buffer = io.BytesIO()
    fig.savefig(buffer, format='png', dpi=dpi)
    plt.close(fig)
    write_atomic(path, buffer.getvalue())
    return path


def tsv_cell(v: Any) -> str:
    """A value as a TSV cell: floats with 3 decimals, None empty."""
    return '' if v is None else (f'{v:.3f}' if isinstance(v, float) else str(v))


def write_tsv(path: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A whole TSV (a header line, then one line per row, :func:`tsv_cell`) at ``path``; returns ``path``."""
    write_atomic(path, ''.join('\t'.join(tsv_cell(v) for v in r) + '\n'
                               for r in [list(columns)] + [list(r) for r in rows]))
    return path


def save_json(path: str, value: Any) -> None:
    """``value`` as indented JSON at ``path`` (its folder made), and ``wrote <path>`` on stdout."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    write_json(path, value, indent=1, sort_keys=False)
    print(f'wrote {path}', flush=True)
