"""What ``run_mission.sh`` (:mod:`cnr_mission.run`) and ``two_host_mission`` (:mod:`cnr_mission.two_host`) share:
the options of the link and of the managed modules, and the mission's "not found" exit status. ROS-free."""
from __future__ import annotations

import argparse
from typing import Callable

EXIT_NOT_FOUND = 3              # the mission ended without finding the hotspot (the mission monitor's status)
DEFAULT_TASK = 'patrol'         # the task of --network-aware without one (config/decision.yaml tasks)


def add_link_arguments(ap: argparse.ArgumentParser, path: Callable[[str], str] = str) -> None:
    """The link options (``two_host_mission`` and ``run_mission.sh``); ``path`` converts the two file names."""
    ap.add_argument('--delay', type=float, metavar='MS', help='one-way delay per direction [ms]')
    ap.add_argument('--rate', type=float, metavar='MBIT', help='rate per direction [Mbit/s], 0 = unlimited')
    ap.add_argument('--loss', type=float, metavar='PCT', help='loss per direction [%%]')
    ap.add_argument('--trace', type=path, metavar='FILE', help='link trace (TSV, testbed.sh trace) played from the '
                    'start')
    ap.add_argument('--link-map', type=path, metavar='FILE', help='link-quality map by robot position (testbed.sh '
                    'follow, e.g. config/link_map_corridor.yaml)')


def add_migration_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of managed modules (``two_host_mission`` and ``run_mission.sh``)."""
    ap.add_argument('--migration', action='store_true', help='the modules of config/migration.yaml are managed by '
                    'migration_manager (start where --placement says, move at run time)')
    ap.add_argument('--rule', action='store_true', help='--migration, and migration_rule moves modules by the link '
                    'quality (config/migration.yaml rule)')
    ap.add_argument('--network-aware', metavar='TASK', nargs='?', const=DEFAULT_TASK, default='',
                    help=f"--migration, and network_monitor's migration_decider places the modules of TASK "
                         f"(config/decision.yaml tasks, default {DEFAULT_TASK}) at the start, re-decides while the "
                         f"mission runs and evaluates it at the end")
