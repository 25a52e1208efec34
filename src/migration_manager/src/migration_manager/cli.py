"""Ask the migration manager to move a module between the robot and the cloud, or show where each module runs.

    rosrun migration_manager migrate MODULE robot|cloud [--mode cold|hot]      (or launch_scripts/migrate.sh)
    rosrun migration_manager migrate --placement

MODULE: move_base, local_mapcell_manager, global_goal_manager or mfg (config/migration.yaml modules). The
manager runs on the robot's master: on the testbed, run this inside the robot's namespace
(ip netns exec robot launch_scripts/migrate.sh ... --host 10.77.0.1). See src/migration_manager/README.md.
Exit status: 0 done, 1 rolled back or failed, 2 refused (bad module, host or mode), 3 no master or no
migration manager answering.
"""
from __future__ import annotations

import math
import os
import sys
from typing import Dict, List, Optional

import rospy

from cnr_harness.script import Parser, ScriptError, master_address, master_up, port_number
from cnr_msgs.msg import Placement
from cnr_msgs.srv import Migrate, MigrateResponse
from migration_manager.codes import MODE, OUTCOME_WORD, TARGET

SERVICE = '/migration_manager/migrate'


def parse_placement(text: str) -> Dict[str, str]:
    """``migrate --placement``'s output -> {module: host it is active on ('-': none)}; modules being migrated
    are left out (for scripts that run the command in another network namespace)."""
    return {r.split()[0]: r.split()[1] for r in text.splitlines()
            if len(r.split()) >= 2 and '(migrating)' not in r}


def main(argv: Optional[List[str]] = None, prog: str = 'migrate') -> int:
    args = rospy.myargv(sys.argv)[1:] if argv is None else argv
    parser = Parser(prog, __doc__)
    parser.add_argument('module', nargs='?', help='e.g. mfg, move_base, local_mapcell_manager, global_goal_manager')
    parser.add_argument('host', nargs='?', help='robot or cloud')
    parser.add_argument('--mode', choices=[w for w in MODE if w], default='', help='default: hot if the module keeps a '
                        'hot standby (config/migration.yaml hot_standby), else cold')
    parser.add_argument('--placement', action='store_true', help='print where each module is active and exit')
    parser.add_argument('--timeout', type=float, default=10.0, help='s to wait for the manager (default 10)')
    parser.add_argument('--host', dest='master_host', metavar='H',
                        help="the robot master's host (default: ROS_MASTER_URI, else localhost)")
    parser.add_argument('--port', type=port_number, metavar='P', help='its port (default: ROS_MASTER_URI, else 11311)')
    a = parser.parse_args(args)
    if not a.placement and (not a.module or not a.host):
        parser.error('give MODULE HOST, or --placement')
    if not a.placement and a.host not in TARGET:
        print(f'migrate: {a.module} -> {a.host}: refused (host must be one of {", ".join(TARGET)})', file=sys.stderr)
        sys.exit(2)
    try:
        master_address(a.master_host, a.port)
    except ScriptError as exc:
        parser.error(str(exc))
    if not master_up():
        print(f'{prog}: no master at {os.environ["ROS_MASTER_URI"]}', file=sys.stderr)
        sys.exit(3)
    rospy.init_node('migrate', anonymous=True, disable_signals=True)
    if a.placement:
        try:
            msg = rospy.wait_for_message('/migration_manager/placement', Placement, a.timeout)
        except rospy.ROSException:
            print(f'migrate: no placement from /migration_manager within {a.timeout:g} s', file=sys.stderr)
            sys.exit(3)
        for module, host, term, moving in zip(msg.modules, msg.hosts, msg.terms, msg.migrating):
            print(f'{module:24s} {host or "-":6s} term {term}{"  (migrating)" if moving else ""}')
        sys.exit(0)
    try:
        rospy.wait_for_service(SERVICE, a.timeout)
    except rospy.ROSException:
        print(f'migrate: {SERVICE} not available within {a.timeout:g} s (is the migration manager running?)',
              file=sys.stderr)
        sys.exit(3)
    res = rospy.ServiceProxy(SERVICE, Migrate)(a.module, TARGET[a.host], MODE[a.mode])
    down = f'; hand-over {1000 * res.downtime:.0f} ms' if not math.isnan(res.downtime) else ''
    print(f'migration {res.id}: {a.module} -> {a.host}: {OUTCOME_WORD[res.outcome]} (term {res.term}, '
          f'{res.duration:.2f} s{down}): {res.message}')
    sys.exit(0 if res.ok else 2 if res.outcome == MigrateResponse.REFUSED else 1)


if __name__ == '__main__':
    main(prog='migrate.sh')
