"""What every bench/experiment entry point shares: its parser, named after the script that runs it, and the root
check.

The launch_scripts wrappers start an entry point through common.sh's ``cnr_python_entry``, which exports the
script's name as ``CNR_PROG``: usage lines, errors and the command on a results page then name the script as typed.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional, Sequence

EXIT_USAGE = 2


def prog_name(module: str) -> str:
    """The wrapper script's name (``CNR_PROG``), or ``python3 -m <module>`` when run directly."""
    if module == '__main__':
        spec = getattr(sys.modules['__main__'], '__spec__', None)
        module = spec.name if spec else os.path.basename(sys.argv[0])
    return os.environ.get('CNR_PROG') or f'python3 -m {module}'


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (``prog: message (see --help)``) and exit status 2."""

    def error(self, message: str):
        print(f'{self.prog}: {message} (see --help)', file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def parser(module: str, doc: Optional[str]) -> Parser:
    """The entry point's parser: ``--help`` shows ``doc`` (its docstring) as written."""
    return Parser(prog=prog_name(module), description=(doc or '').strip(),
                  formatter_class=argparse.RawDescriptionHelpFormatter)


def command(ap: argparse.ArgumentParser, argv: Optional[Sequence[str]]) -> str:
    """The command line as typed (for a results page): the script's name and its arguments."""
    from cnr_benchmarks.results import command_line
    return command_line(ap.prog, list(sys.argv[1:] if argv is None else argv))


def require_root(prog: str, why: str) -> None:
    """Exit with status 2 and one line naming ``why`` unless running as root."""
    if os.geteuid() != 0:
        print(f'{prog}: needs root ({why})', file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


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
