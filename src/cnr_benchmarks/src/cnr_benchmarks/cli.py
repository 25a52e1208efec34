"""What the bench/experiment entry points add to the user scripts' parser (:class:`cnr_harness.script.Parser`,
named after the launch_scripts wrapper that runs the entry point): the command line for a results page, the root
check and the argument types they share.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional, Sequence

from cnr_harness.script import Parser, require_root  # noqa: F401  (the entry points import it from here)

__all__ = ['Parser', 'command', 'comma_list', 'positive_int', 'require_root', 'sim_part_parser']


def command(ap: argparse.ArgumentParser, argv: Optional[Sequence[str]]) -> str:
    """The command line as typed (for a results page): ``launch_scripts/<script>`` and its arguments."""
    from cnr_benchmarks.results import command_line
    return command_line(f'launch_scripts/{ap.prog}', list(sys.argv[1:] if argv is None else argv))


def sim_part_parser(doc: str, json_name: str) -> argparse.ArgumentParser:
    """The parser of one part of bench_sim.sh (run by cnr_benchmarks.sim_suite): ``--out``, the part's JSON,
    default ``bench_results/sim/<json_name>``."""
    from cnr_benchmarks.results import scratch_dir
    ap = argparse.ArgumentParser(description=doc.split('\n')[0])
    ap.add_argument('--out', default=os.path.join(scratch_dir('sim'), json_name), help='default %(default)s')
    return ap


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f'expected a positive integer, got {text!r}')
    return value


def comma_list(choices: Sequence[str]):
    """argparse type: comma-separated names, each one of ``choices``."""
    def parse(text: str) -> List[str]:
        names = [n for n in text.split(',') if n]
        bad = [n for n in names if n not in choices]
        if bad or not names:
            raise argparse.ArgumentTypeError(f'expected a comma-separated subset of {",".join(choices)}, got {text!r}')
        return names
    return parse
