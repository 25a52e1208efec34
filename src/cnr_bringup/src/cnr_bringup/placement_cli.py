"""``rosrun cnr_bringup placement``: list, show and use the placements of ``config/placements.yaml``.

    placement list                      named placements, one per line
    placement show NAME|FILE            where each module runs, what the bridges let cross
    placement args NAME|FILE HOST       the launch arguments (module:=true|false) for HOST

``--catalog FILE`` reads another catalog (default: ``$(find cnr_config)/config/placements.yaml``).
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import List, Optional

from cnr_params.config import ConfigError, EXIT_CONFIG
from cnr_bringup.placement import describe, launch_args, load_catalog


def default_catalog() -> str:
    import rospkg
    return os.path.join(rospkg.RosPack().get_path('cnr_config'), 'config', 'placements.yaml')


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='placement', description=__doc__.split('\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--catalog', help='placements YAML (default: config/placements.yaml of cnr_config)')
    sub = ap.add_subparsers(dest='cmd', required=True)
    sub.add_parser('list')
    sh = sub.add_parser('show')
    sh.add_argument('placement')
    ar = sub.add_parser('args')
    ar.add_argument('placement')
    ar.add_argument('host')
    args = ap.parse_args(argv)
    try:
        catalog = load_catalog(args.catalog or default_catalog())
        if args.cmd == 'list':
            print('\n'.join(catalog.named))
        elif args.cmd == 'show':
            print(describe(catalog.placement(args.placement)))
        else:
            if args.host not in catalog.hosts:
                raise ConfigError('placement args', 'host', f"unknown host {args.host!r} ({', '.join(catalog.hosts)})")
            print(' '.join(launch_args(catalog.placement(args.placement), args.host)))
    except ConfigError as exc:
        print(f'placement: {exc}', file=sys.stderr)
        return EXIT_CONFIG
    return 0
