"""README command (1): the navigation demo in the thesis's lab corridor.

Sets up the workspace (launch_scripts/setup.sh), starts a master (default port 11311, or --port, or
ROS_MASTER_URI), brings up the simulated TurtleBot 2 with navigation (bringup.sh), drives it through the goal
sequence printing progress (cnr_navigation's goal_sequencer), then stops everything it started.
Exit status: 0 every goal reached, 1 some goal failed, 2 bad configuration, 130 interrupted.
"""
from __future__ import annotations

import os
import sys
from typing import List, Optional

from cnr_bringup.bringup import add_map_arguments, map_file, start_robot
from cnr_harness.script import WS, Parser, Processes, ScriptError, log, master_address, master_up, port_number, \
    run, setup_workspace

PROG = 'run_demo.sh'
SERVER_TIMEOUT = 180        # wall s the goal sequencer waits for move_base (start-up of a fresh bring-up)


def demo(argv: Optional[List[str]]) -> int:
    ap = Parser(PROG, __doc__)
    add_map_arguments(ap)
    ap.add_argument('--port', type=port_number, help='master port (default: ROS_MASTER_URI, else 11311)')
    ap.add_argument('--goals', type=os.path.realpath, metavar='FILE',
                    help='goal file (default config/goals_<map>.yaml)')
    args = ap.parse_args(argv)
    goals = args.goals or os.path.join(WS, 'config', f'goals_{args.map}.yaml')
    if not os.path.isfile(goals):
        raise ScriptError(f'goal file not found: {goals}')
    map_file(args.map)
    setup_workspace()
    _, port = master_address(None, args.port)
    if master_up():
        raise ScriptError(f'a master already runs at {os.environ["ROS_MASTER_URI"]}; stop it or choose --port')
    with Processes() as procs:
        procs.ensure_master(PROG, port)
        start_robot(procs, args.map, args.rtf)
        rc = procs.start(['rosrun', 'cnr_navigation', 'goal_sequencer', '--goals', goals, '--server-timeout',
                          str(SERVER_TIMEOUT)]).wait()
        log(PROG, 'demo finished: every goal reached' if rc == 0 else f'demo finished: some goals failed (exit {rc})')
        return rc


def main(argv: Optional[List[str]] = None) -> int:
    return run(lambda: demo(argv), PROG)


if __name__ == '__main__':
    sys.exit(main())
