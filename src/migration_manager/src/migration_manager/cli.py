"""``rosrun migration_manager migrate MODULE HOST [--mode cold|hot]`` (and ``launch_scripts/migrate.sh``): ask
the migration manager to move a module and print the outcome; ``--placement`` prints where each module is.

Exit status: 0 done, 1 rolled back or failed, 2 refused (bad module, host or mode), 3 no manager answering.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Dict, List, Optional

import rospy

from cnr_msgs.msg import Placement
from cnr_msgs.srv import Migrate, MigrateResponse
from migration_manager.codes import MODE, OUTCOME_WORD, TARGET

SERVICE = '/migration_manager/migrate'


def parse_placement(text: str) -> Dict[str, str]:
    """``migrate --placement``'s output -> {module: host it is active on ('-': none)}; modules being migrated
    are left out (for scripts that run the command in another network namespace)."""
    return {r.split()[0]: r.split()[1] for r in text.splitlines()
            if len(r.split()) >= 2 and '(migrating)' not in r}


def main(argv: Optional[List[str]] = None) -> int:
    args = rospy.myargv(sys.argv)[1:] if argv is None else argv
    parser = argparse.ArgumentParser(prog='migrate', description='Move a managed module to a host.')
    parser.add_argument('module', nargs='?', help='e.g. mfg, move_base, local_mapcell_manager, global_goal_manager')
    parser.add_argument('host', nargs='?', help='robot or cloud')
    parser.add_argument('--mode', choices=[w for w in MODE if w], default='', help='default: hot if the module keeps a '
                        'hot standby (config/migration.yaml hot_standby), else cold')
    parser.add_argument('--placement', action='store_true', help='print where each module is active and exit')
    parser.add_argument('--timeout', type=float, default=10.0, help='s to wait for the manager (default 10)')
    a = parser.parse_args(args)
    if not a.placement and (not a.module or not a.host):
        parser.error('give MODULE HOST, or --placement')
    if not a.placement and a.host not in TARGET:
        print(f'migrate: {a.module} -> {a.host}: refused (host must be one of {", ".join(TARGET)})', file=sys.stderr)
        sys.exit(2)
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
