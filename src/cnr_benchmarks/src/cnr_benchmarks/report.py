"""Running a benchmark: TSV rows logged as they are measured, markdown tables, interrupts, child processes, and
the testbed benchmarks' common arguments and set-up (the results page: :mod:`cnr_benchmarks.results`)."""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import IO, Callable, Dict, Iterable, Iterator, List, NoReturn, Optional, Sequence, Tuple, TypeVar

from cnr_benchmarks.results import WS, results_dir, scratch_dir, tsv_cell
from cnr_harness.script import EXIT_INTERRUPTED, require_root

T = TypeVar('T')


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
        self._f.write('\t'.join(tsv_cell(values[c]) for c in self.columns) + '\n')
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def move_aside(path: str) -> None:
    """Keep an earlier run's folder (or file) as ``<path>.prev<unix time>`` so a new one starts empty; nothing
    when there is none."""
    if os.path.exists(path):
        os.replace(path, f'{path}.prev{int(time.time())}')


def markdown_table(header: Sequence[str], rows: Iterable[Sequence]) -> str:
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    for r in rows:
        lines.append('| ' + ' | '.join(_cell(c) for c in r) + ' |')
    return '\n'.join(lines)


def _cell(c) -> str:
    if isinstance(c, float):
        return '–' if c != c else f'{c:.2f}'
    return str(c)


def stop_on_signals() -> None:
    """SIGTERM, and SIGINT even where the shell that started a background job ignored it, raise
    KeyboardInterrupt: a long run writes what it measured and stops its testbed (for a command's ``__main__``)."""
    def _interrupt(*_) -> None:
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, _interrupt)
    signal.signal(signal.SIGINT, _interrupt)


def run_main(main: Callable[[], int], on_interrupt: str = '') -> NoReturn:
    """A long run's ``__main__``: :func:`stop_on_signals`, then exit with ``main()``'s status; an interrupt says
    ``on_interrupt`` (what was kept) and exits with status 130."""
    stop_on_signals()
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        if on_interrupt:
            print(f'interrupted: {on_interrupt}', file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)


def call(argv: Sequence[str], output: Optional[IO] = None) -> int:
    """subprocess.call (its stdout and stderr to ``output`` if given), except that an interrupt stops the child
    with SIGTERM and waits for its clean-up (subprocess.call sends SIGKILL, which leaves a testbed's namespaces
    and processes behind)."""
    child = subprocess.Popen(list(argv), stdout=output, stderr=subprocess.STDOUT if output else None)
    try:
        return child.wait()
    except KeyboardInterrupt:
        child.terminate()
        while True:
            try:
                child.wait()
                break
            except KeyboardInterrupt:   # a second interrupt: the child is already stopping
                continue
        raise


def progress(msg: str) -> None:
    print(msg, flush=True)


def add_resumable_arguments(ap: argparse.ArgumentParser, experiment: str) -> None:
    """``--out`` (the page's folder) and ``--fresh`` of an experiment made of resumable testbed runs."""
    ap.add_argument('--out', default=results_dir(experiment), help="the page's folder (default %(default)s)")
    ap.add_argument('--fresh', action='store_true', help='start over: the runs made before are removed')


def resumable_scratch(prog: str, args: argparse.Namespace, experiment: str) -> str:
    """The testbed experiment's scratch folder (root checked first); ``--fresh`` removes the runs made before."""
    require_root(prog, 'the testbed: network namespaces, TUN devices, cgroups')
    scratch = scratch_dir(experiment)
    if args.fresh:
        shutil.rmtree(os.path.join(scratch, 'runs'), ignore_errors=True)
    return scratch


def pending_runs(prog: str, runs: int, keys: Sequence[str],
                 folder: Callable[[str, int], str]) -> Iterator[Tuple[int, str, str, str]]:
    """A resumable experiment's runs, run ``i`` of every key before run ``i + 1``: yields (i, key, folder,
    progress prefix ``[prog] [n/total]``) for each run whose folder holds no ``summary.json`` yet, and says of the
    others that they are kept."""
    total, n = len(keys) * runs, 0
    for i in range(1, runs + 1):
        for key in keys:
            n += 1
            where = folder(key, i)
            if os.path.exists(os.path.join(where, 'summary.json')):
                progress(f'[{prog}] [{n}/{total}] {key} run {i}: done before, kept')
                continue
            yield i, key, where, f'[{prog}] [{n}/{total}]'


def finished_runs(runs: int, keys: Sequence[str], folder: Callable[[str, int], str],
                  load: Callable[[str, str, int], Optional[T]]) -> List[T]:
    """Every finished run's ``load(folder, key, i)`` (None: unfinished, left out), key by key."""
    return [r for key in keys for i in range(1, runs + 1) for r in [load(folder(key, i), key, i)] if r is not None]


def group(rows: List[Dict], *keys: str) -> Dict[tuple, List[Dict]]:
    out: Dict[tuple, List[Dict]] = {}
    for r in rows:
        out.setdefault(tuple(r[k] for k in keys), []).append(r)
    return out


def add_common_arguments(ap: argparse.ArgumentParser, default_rtts: str, experiment: str) -> None:
    """--rtts, --out (default docs/results/<experiment>) and --config of the testbed benchmarks."""
    ap.add_argument('--rtts', default=default_rtts, help='link RTTs in ms (comma-separated)')
    ap.add_argument('--out', default=results_dir(experiment), help="the page's folder (default %(default)s)")
    ap.add_argument('--config', default=os.path.join(WS, 'config', 'testbed.yaml'))


def parse_rtts(prog: str, text: str) -> List[float]:
    """``'0,20,50'`` -> ``[0.0, 20.0, 50.0]``; a one-line error and exit status 2 otherwise."""
    try:
        rtts = [float(x) for x in text.split(',')]
    except ValueError:
        rtts = []
    if not rtts or any(not r >= 0 for r in rtts):
        print(f'{prog}: --rtts: expected non-negative numbers separated by commas, got {text!r}', file=sys.stderr)
        raise SystemExit(2)
    return rtts


class BenchRun:
    """A benchmark on the testbed: parsed RTTs, the TSV log of the rows as measured (in
    ``bench_results/<experiment>/``), a work directory with a fresh bridge secret, and the testbed (instance
    ``cnrbench``) brought up on entry and down on exit, however the run ends."""

    def __init__(self, prog: str, args: argparse.Namespace, experiment: str, tsv_name: str,
                 columns: Sequence[str]) -> None:
        self.rtts = parse_rtts(prog, args.rtts)
        from cnr_testbed.api import Testbed
        self.testbed = Testbed(args.config, {'name': 'cnrbench', 'robot.namespace': 'cnrbench-robot',
                                             'cloud.namespace': 'cnrbench-cloud'})
        self.log = TsvLog(os.path.join(scratch_dir(experiment), tsv_name), columns)
        self.work = tempfile.mkdtemp(prefix=f'{prog}-')
        self.secret = os.path.join(self.work, 'secret')
        with open(self.secret, 'w') as f:
            f.write(os.urandom(16).hex())

    def say_written(self, out: str) -> None:
        """Where the page, the rows as measured and the node logs are."""
        print(f'wrote {os.path.join(out, "README.md")} and its tables and figures (rows as measured in {self.log.path}, '
              f'node logs in {self.work})', flush=True)

    def __enter__(self) -> 'BenchRun':
        try:
            self.testbed.up()
        except BaseException:
            self.log.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.testbed.down()
        finally:
            self.log.close()
