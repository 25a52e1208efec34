"""Start a ROS master (roscore: rosmaster + rosout) on a chosen address, like ``roscore -p``.

Address: --host/--port, else ROS_MASTER_URI, else http://localhost:11311. Runs in the foreground; Ctrl-C
stops it. Prints the ROS_MASTER_URI to export in other shells.
"""
from __future__ import annotations

import os
import sys
from typing import List, Optional

from cnr_harness.script import Parser, Processes, ScriptError, log, master_address, master_up, port_number, run

PROG = 'ros_master.sh'


def ros_master(argv: Optional[List[str]]) -> int:
    ap = Parser(PROG, __doc__)
    ap.add_argument('--host', help='master host (default: ROS_MASTER_URI, else localhost)')
    ap.add_argument('--port', type=port_number, help='master port (default: ROS_MASTER_URI, else 11311)')
    ap.add_argument('--multi-master', action='store_true',
                    help="one host's master of several joined by multimaster_bridge: its calls to the other host's "
                         "nodes (a dead link hangs them) never hold up its own nodes' (cnr_harness.rosmaster)")
    args = ap.parse_args(argv)
    _, port = master_address(args.host, args.port)
    uri = os.environ['ROS_MASTER_URI']
    if master_up():
        raise ScriptError(f'a master already answers at {uri}')
    with Processes() as procs:
        procs.ensure_master(PROG, port, args.multi_master)
        log(PROG, f'master up: export ROS_MASTER_URI={uri}   (Ctrl-C to stop)')
        return procs.popens[0].wait()


def main(argv: Optional[List[str]] = None) -> int:
    return run(lambda: ros_master(argv), PROG)


if __name__ == '__main__':
    sys.exit(main())
