"""``check_scenario FILE``: validate a whole scenario file before anything is launched.

On success prints one line ``NAME MAP X Y YAW`` (the scenario's name, the resolved map_server YAML, the start
pose in m, m, rad) for the shell to ``read``, exit 0. On a problem prints one line ``FILE: field: problem`` to
stderr, exit 2. ``--config-dir`` and ``--maps-dir`` default to cnr_config's ``config/`` and ``maps/``.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional

from cnr_mission.core.scenario import validate_scenario
from cnr_params import ConfigError
from cnr_params.config import EXIT_CONFIG


def _cnr_config_dir(sub: str) -> str:
    import rospkg
    try:
        return os.path.join(rospkg.RosPack().get_path('cnr_config'), sub)
    except rospkg.ResourceNotFound:
        raise ConfigError('cnr_config', '', f'package not found (source the workspace or pass --{sub}-dir)') from None


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='check_scenario', description=__doc__.split('\n\n')[0])
    parser.add_argument('file', help='scenario YAML (e.g. config/scenarios/corridor.yaml)')
    parser.add_argument('--config-dir', help="the nodes' default files (default: $(find cnr_config)/config)")
    parser.add_argument('--maps-dir', help='folder of relative map names (default: $(find cnr_config)/maps)')
    args = parser.parse_args(argv)
    try:
        sc = validate_scenario(args.file, args.config_dir or _cnr_config_dir('config'),
                               args.maps_dir or _cnr_config_dir('maps'))
    except ConfigError as exc:
        sys.stderr.write(f'{exc}\n')
        return EXIT_CONFIG
    print(f'{sc.name} {sc.map_file} {sc.start.x!r} {sc.start.y!r} {sc.start.yaw!r}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
