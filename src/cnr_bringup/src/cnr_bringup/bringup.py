"""Bring up the simulated TurtleBot 2 (simulator, map_server, move_base) on a master.

Starts a master first if none answers at the address (--host/--port, else ROS_MASTER_URI, else
localhost:11311). Runs in the foreground; Ctrl-C stops everything it started.
  --rtf 1.0 real time (default), 5 = five times faster, 0 = as fast as possible.
  --controller-frequency: move_base's control rate (default: config/navigation/move_base.yaml).
Arguments after -- go to roslaunch as they are (robot.launch arg:=value).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from typing import List, Optional

from cnr_harness.script import WS, Parser, Processes, ScriptError, log, master_address, port_number, run

PROG = 'bringup.sh'
MAPS = ('corridor', 'datacenter')
START = {'corridor': ['0.5', '0.0', '0.0'], 'datacenter': ['1.0', '1.0', '0.0']}     # x y yaw, by map


def number(text: str) -> str:
    """A decimal number, kept as written (an argparse ``type``)."""
    if not re.fullmatch(r'-?[0-9]+(\.[0-9]+)?', text):
        raise argparse.ArgumentTypeError(f"not a number: '{text}'")
    return text


def add_map_arguments(ap: argparse.ArgumentParser) -> None:
    """--map and --rtf (bringup.sh and run_demo.sh)."""
    ap.add_argument('--map', default='corridor', metavar='corridor|datacenter|FILE.yaml',
                    help='maps/NAME.yaml or a map_server YAML file (default corridor)')
    ap.add_argument('--rtf', type=number, default='1.0', metavar='FACTOR', help='real-time factor (default 1.0)')


def map_file(name: str) -> str:
    path = os.path.join(WS, 'maps', f'{name}.yaml') if name in MAPS else os.path.realpath(name)
    if not os.path.isfile(path):
        raise ScriptError(f'map file not found: {path}')
    return path


def start_robot(procs: Processes, map_name: str, rtf: str, pose: Optional[List[str]] = None,
                obstacles: bool = False, navigation: bool = True, controller_frequency: Optional[str] = None,
                extra: Optional[List[str]] = None) -> subprocess.Popen:
    """Start robot.launch (through cnr_launch: it stops at once with exit 2 when a node reports a configuration
    error) on the master of ``ROS_MASTER_URI``."""
    path = map_file(map_name)
    x, y, yaw = pose or START.get(map_name, START['corridor'])
    log(PROG, f'bringing up the TurtleBot on {os.environ["ROS_MASTER_URI"]} (map {path}, real-time factor {rtf})')
    return procs.start(['rosrun', 'cnr_bringup', 'cnr_launch', 'cnr_bringup', 'robot.launch', f'map:={path}',
                        f'real_time_factor:={rtf}', f'x:={x}', f'y:={y}', f'a:={yaw}',
                        f'obstacles:={str(obstacles).lower()}', f'navigation:={str(navigation).lower()}',
                        *([f'controller_frequency:={controller_frequency}'] if controller_frequency else []),
                        *(extra or [])])


def parse_args(argv: Optional[List[str]]) -> argparse.Namespace:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = Parser(PROG, __doc__)
    add_map_arguments(ap)
    ap.add_argument('--host', help='master host (default: ROS_MASTER_URI, else localhost)')
    ap.add_argument('--port', type=port_number, help='master port (default: ROS_MASTER_URI, else 11311)')
    ap.add_argument('--pose', nargs=3, type=number, metavar=('X', 'Y', 'YAW'),
                    help='start pose in the map frame [m, m, rad] (default 0.5 0 0; datacenter 1 1 0)')
    ap.add_argument('--obstacles', action='store_true', help='the simulator loads config/obstacles_corridor.yaml')
    ap.add_argument('--no-nav', dest='navigation', action='store_false', help='without move_base')
    ap.add_argument('--controller-frequency', type=number, metavar='HZ', help="move_base's control rate")
    ap.add_argument('extra', nargs='*', metavar='-- ARG:=VALUE', help='extra roslaunch arguments')
    args = ap.parse_args(argv)
    if args.extra and '--' not in argv:
        ap.error(f'unrecognized arguments: {" ".join(args.extra)}')
    return args


def bringup(argv: Optional[List[str]]) -> int:
    args = parse_args(argv)
    map_file(args.map)
    _, port = master_address(args.host, args.port)
    with Processes() as procs:
        procs.ensure_master(PROG, port)
        launch = start_robot(procs, args.map, args.rtf, args.pose, args.obstacles, args.navigation,
                             args.controller_frequency, args.extra)
        return launch.wait()


def main(argv: Optional[List[str]] = None) -> int:
    return run(lambda: bringup(argv), PROG)


if __name__ == '__main__':
    sys.exit(main())
