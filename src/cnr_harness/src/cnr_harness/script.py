"""What the user scripts of ``launch_scripts/`` share: a parser whose errors are one line, the master address,
a master started when none answers, and the processes a script starts, stopped when it ends.

ROS-free: masters are reached over XML-RPC and processes stopped through :mod:`cnr_harness`.

A script's entry point looks like::

    def main(argv=None) -> int:
        args = Parser('bringup.sh', __doc__).parse_args(argv)   # --help is the module docstring
        with Processes() as procs:                              # SIGINT/SIGTERM raise Interrupted
            ...                                                 # raise ScriptError('one line') -> exit 2
    if __name__ == '__main__':
        sys.exit(run(main))
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
from typing import Callable, List, NoReturn, Optional, Sequence, Tuple

from cnr_harness import WaitTimeout, master_answers, stop_process, wait_until
from cnr_params.config import EXIT_CONFIG

EXIT_INTERRUPTED = 130             # the status of a run stopped by Ctrl-C (128 + SIGINT), as a shell reports it

# the workspace (this file is <ws>/src/cnr_harness/src/cnr_harness/script.py)
WS = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
DEFAULT_MASTER_URI = 'http://localhost:11311'
MASTER_START_TIMEOUT = 20.0         # s a started roscore has to answer


class ScriptError(Exception):
    """A problem the script states in one line (``<script>: <problem>``) before it exits with status 2."""


class Interrupted(Exception):
    """SIGINT or SIGTERM arrived while :class:`Processes` was in charge."""


class Parser(argparse.ArgumentParser):
    """The script's parser: ``--help`` shows ``doc`` (the entry module's docstring) under the usage; a bad
    option is one line naming it and exit status 2 (subcommands' parsers too)."""

    def __init__(self, prog: Optional[str] = None, doc: Optional[str] = None, **kwargs) -> None:
        kwargs.setdefault('formatter_class', argparse.RawDescriptionHelpFormatter)
        if doc is not None:
            kwargs['description'] = doc
        super().__init__(prog=prog, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_CONFIG, f'{self.prog}: {message} (see --help)\n')


def require_root(prog: str, why: str) -> None:
    """Exit with status 2 and one line naming ``why`` unless running as root."""
    if os.geteuid() != 0:
        print(f'{prog}: needs root ({why})', file=sys.stderr)
        raise SystemExit(EXIT_CONFIG)


def log(prog: str, text: str) -> None:
    """A progress line ``[<script>] text``."""
    print(f'[{prog}] {text}', flush=True)


def run(main: Callable[[], int], prog: str) -> int:
    """Call a script's ``main``: a :class:`ScriptError` is one line on stderr and exit status 2, an
    :class:`Interrupted` exit status 130."""
    try:
        return main()
    except ScriptError as exc:
        print(f'{prog}: {exc}', file=sys.stderr, flush=True)
        return EXIT_CONFIG
    except (Interrupted, KeyboardInterrupt):
        return EXIT_INTERRUPTED


def port_number(text: str) -> int:
    """A master port 1..65535 (an argparse ``type``)."""
    if not re.fullmatch(r'[0-9]+', text) or not 1 <= int(text) <= 65535:
        raise argparse.ArgumentTypeError(f"invalid master port '{text}'")
    return int(text)


def master_address(host: Optional[str] = None, port: Optional[int] = None) -> Tuple[str, int]:
    """The master's host and port: the arguments, else ``ROS_MASTER_URI``, else localhost:11311; exported as
    ``ROS_MASTER_URI`` for this process and the processes it starts. ScriptError for a bad port."""
    env_uri = os.environ.get('ROS_MASTER_URI') or DEFAULT_MASTER_URI
    hostport = env_uri[len('http://'):] if env_uri.startswith('http://') else env_uri
    hostport = hostport[:-1] if hostport.endswith('/') else hostport
    env_host, _, env_port = hostport.rpartition(':')
    host = host or env_host or hostport
    if port is None:
        try:
            port = port_number(env_port or hostport)
        except argparse.ArgumentTypeError as exc:
            raise ScriptError(str(exc)) from None
    os.environ['ROS_MASTER_URI'] = f'http://{host}:{port}'
    return host, port


def master_up(uri: Optional[str] = None) -> bool:
    """Whether a master answers at ``uri`` (default: ``ROS_MASTER_URI``)."""
    return master_answers(uri or os.environ['ROS_MASTER_URI'], '/cnr_script')


def setup_workspace(*options: str) -> None:
    """``launch_scripts/setup.sh [options]``: install what is missing and build; exit status 1 when it fails."""
    if subprocess.call([os.path.join(WS, 'launch_scripts', 'setup.sh'), *options]) != 0:
        raise SystemExit(1)


class Processes:
    """The processes a script starts, each in a process group of its own.

    As a context manager it turns SIGINT and SIGTERM into :class:`Interrupted` and, on leaving, stops every
    process it started, newest first (nodes before their master): SIGINT as roslaunch does, then SIGTERM, then
    SIGKILL (:func:`cnr_harness.stop_process`).
    """

    def __init__(self) -> None:
        self.popens: List[subprocess.Popen] = []
        self._handlers: dict = {}

    def start(self, argv: Sequence[str], **popen_kwargs) -> subprocess.Popen:
        popen = subprocess.Popen(list(argv), start_new_session=True, **popen_kwargs)
        self.popens.append(popen)
        return popen

    def ensure_master(self, prog: str, port: int, multi_master: bool = False) -> None:
        """Start ``roscore -p PORT`` unless a master answers at ``ROS_MASTER_URI``; wait until it answers. With
        ``multi_master``, the master of one host of several (:mod:`cnr_harness.rosmaster`, whose calls to the other
        host's nodes never hold up its own) and rosout instead."""
        if master_up():
            log(prog, f'using the running master at {os.environ["ROS_MASTER_URI"]}')
            return
        log(prog, f'starting {"the master" if multi_master else "roscore"} on port {port}')
        roscore = self.start([sys.executable, '-m', 'cnr_harness.rosmaster', '--core', '-p', str(port)]
                             if multi_master else ['roscore', '-p', str(port)])

        def answers() -> bool:
            if roscore.poll() is not None:
                raise ScriptError(f'roscore failed to start on port {port} (port in use?)')
            return master_up()
        try:
            wait_until(answers, MASTER_START_TIMEOUT, 'the master', interval=0.2)
        except WaitTimeout:
            raise ScriptError(f'no master answered at {os.environ["ROS_MASTER_URI"]} after '
                              f'{MASTER_START_TIMEOUT:.0f} s') from None
        if multi_master:
            self.start(['rosrun', 'rosout', 'rosout'])

    def stop(self) -> None:
        for popen in reversed(self.popens):
            stop_process(popen, timeout=10.0, term_timeout=10.0, kill_timeout=10.0)
        self.popens.clear()

    def _interrupt(self, _signum, _frame) -> None:
        raise Interrupted()

    def __enter__(self) -> 'Processes':
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._handlers[sig] = signal.signal(sig, self._interrupt)
        return self

    def __exit__(self, *exc) -> None:
        for sig in self._handlers:
            signal.signal(sig, signal.SIG_IGN)       # a second Ctrl-C does not cut the clean-up short
        try:
            self.stop()
        finally:
            for sig, handler in self._handlers.items():
                signal.signal(sig, handler)

