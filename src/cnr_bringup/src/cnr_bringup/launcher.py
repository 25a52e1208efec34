"""``cnr_launch``: roslaunch with two rules a mission needs and roslaunch lacks.

1. A node that exits with status 2 (``cnr_params.EXIT_CONFIG``: its configuration is wrong) ends the whole
   launch at once with exit status 2 and is never respawned: respawn is for runtime crashes, and a node
   whose configuration is wrong would only fail again (roslaunch alone respawns it forever, or, for a node
   that is not respawned, keeps the rest of the launch waiting for it).
2. ``--until NODE`` ends the launch quietly when NODE exits and returns NODE's exit status (the way a
   mission's monitor says "done"; roslaunch alone reports a ``required`` node that finished as an error).

Everything else is roslaunch's own machinery (``roslaunch.parent.ROSLaunchParent``): the same output, the
same ``pkg file.launch arg:=value`` arguments, SIGINT/SIGTERM escalation on shutdown. Ctrl-C ends the launch
with status 130.

Usage::

    rosrun cnr_bringup cnr_launch [--until NODE] PACKAGE FILE.launch [arg:=value ...]
    rosrun cnr_bringup cnr_launch [--until NODE] PATH/FILE.launch [arg:=value ...]
"""
from __future__ import annotations

import argparse
import re
import sys
import threading
from typing import List, Optional

from cnr_harness.script import EXIT_INTERRUPTED
from cnr_params.config import EXIT_CONFIG   # a node's one-line configuration error

# roslaunch's lines that say nothing to a person watching a run (the parameter summary, blank lines)
NOISE = re.compile(r'^( \* /|\s*$|.*rosdep view is empty)')


class _Outcome:
    """What ended the launch: written by roslaunch's process-monitor thread, read by the main thread."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.status: Optional[int] = None
        self.reason = ''

    def finish(self, status: int, reason: str) -> None:
        if not self.done.is_set():
            self.status, self.reason = status, reason
            self.done.set()


def _base_name(process_name: str) -> str:
    """roslaunch names processes ``<node name>-<n>``; a namespaced node ``ns/name-<n>``."""
    return process_name.rsplit('-', 1)[0].rsplit('/', 1)[-1]


def _make_listener(outcome: _Outcome, until: Optional[str], pm):
    from roslaunch.pmon import ProcessListener

    class Listener(ProcessListener):
        def process_died(self, process_name: str, exit_code: Optional[int]) -> None:
            # Runs in the process monitor's thread, before it respawns anything: shutting the monitor down
            # here means a node that failed its configuration is not started again.
            if exit_code == EXIT_CONFIG:
                outcome.finish(EXIT_CONFIG, f'{_base_name(process_name)} exited with a configuration error '
                                            f'(exit status 2, its one-line error is above)')
            elif until is not None and _base_name(process_name) == until:
                outcome.finish(exit_code or 0, f'{until} finished (exit status {exit_code or 0})')
            else:
                return
            pm.shutdown()

    return Listener()


def parse_args(argv: List[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='cnr_launch', description='roslaunch that ends at once with status 2 when a node exits with a '
        'configuration error, and optionally ends (quietly) when one node exits.')
    parser.add_argument('--until', metavar='NODE', help='end the launch when this node exits; its exit status '
                        'becomes ours')
    parser.add_argument('launch', nargs='+', metavar='ARG', help='PACKAGE FILE.launch | PATH.launch, then arg:=value')
    return parser.parse_args(argv)


def main(argv: Optional[List[str]] = None) -> int:
    import roslaunch
    import roslaunch.parent
    import roslaunch.pmon
    import roslaunch.rlutil
    from roslaunch.core import RLException

    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        files = roslaunch.rlutil.resolve_launch_arguments(args.launch)
    except RLException as exc:
        print(f'cnr_launch: {exc}', file=sys.stderr)
        return EXIT_CONFIG
    launch_args = [a for a in args.launch if ':=' in a]
    launch_files = [f for f in files if ':=' not in f]
    if len(launch_files) != 1:
        print(f'cnr_launch: expected one launch file, got {launch_files}', file=sys.stderr)
        return EXIT_CONFIG

    outcome = _Outcome()

    class Parent(roslaunch.parent.ROSLaunchParent):
        def _start_pm(self) -> None:
            super()._start_pm()
            # added before any node starts, so no exit goes unseen (ROSLaunchParent adds its listeners
            # only after launching every node)
            self.pm.add_process_listener(_make_listener(outcome, args.until, self.pm))

    uuid = roslaunch.rlutil.get_or_generate_uuid(None, False)
    roslaunch.configure_logging(uuid)
    parent = Parent(uuid, [(launch_files[0], launch_args)])

    try:
        parent.start()
        parent.spin()            # returns when the process monitor has stopped (and stopped every node)
    except RLException as exc:
        print(f'cnr_launch: {exc}', file=sys.stderr)
        parent.shutdown()
        return EXIT_CONFIG
    # roslaunch owns SIGINT/SIGTERM/SIGHUP (its handler re-installs itself over any other); it records that
    # one arrived in this flag
    if getattr(roslaunch.pmon, '_shutting_down', False):
        return EXIT_INTERRUPTED
    if outcome.done.is_set():
        if outcome.status != 0:
            print(f'cnr_launch: {outcome.reason}', file=sys.stderr)
        return int(outcome.status)
    return 0
