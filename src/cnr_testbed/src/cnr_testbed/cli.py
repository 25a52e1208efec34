"""``testbed.sh`` — robot and cloud network namespaces joined by the user-space link emulator.

    testbed.sh up [--config FILE] [--name N]       create namespaces + emulator (needs root)
    testbed.sh down | status [--json]
    testbed.sh set [--dir up|down|both] [--delay MS] [--jitter MS] [--loss PCT] [--rate MBIT]
                   [--queue PKTS] [--outage on|off] [--reorder on|off]
    testbed.sh trace FILE                          follow a TSV trace of conditions (Ctrl-C stops)
    testbed.sh follow [--map FILE]                 follow the robot through a link-quality map (ROS)
    testbed.sh robot [--uncapped] -- CMD [ARGS...]  run CMD on the robot: its namespace, inside its CPU cap
    testbed.sh cpu [--json]                        the robot's CPU cap: limit, CPU used, throttling

Delays are one-way per direction: --delay 25 on both directions adds 50 ms of RTT.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

from cnr_harness.script import WS, Parser
from cnr_params import ConfigError


def _onoff(v: str) -> bool:
    if v.lower() in ('on', 'true', '1', 'yes'):
        return True
    if v.lower() in ('off', 'false', '0', 'no'):
        return False
    raise argparse.ArgumentTypeError(f"expected on or off, got '{v}'")


def _nonneg(v: str) -> float:
    try:
        x = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: '{v}'") from None
    if not x >= 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {v}')
    return x


def parser() -> argparse.ArgumentParser:
    ap = Parser('testbed.sh', __doc__.split('\n')[0], epilog=__doc__)
    ap.add_argument('--config', default=os.path.join(WS, 'config', 'testbed.yaml'))
    ap.add_argument('--name', help='instance name (default from the config); namespaces become NAME-robot/NAME-cloud '
                                   'when given')
    sub = ap.add_subparsers(dest='cmd', required=True)
    sub.add_parser('up')
    sub.add_parser('down')
    st = sub.add_parser('status')
    st.add_argument('--json', action='store_true')
    s = sub.add_parser('set')
    s.add_argument('--dir', default='both', choices=('up', 'down', 'both'))
    s.add_argument('--delay', type=_nonneg, help='one-way delay [ms]')
    s.add_argument('--jitter', type=_nonneg, help='[ms]')
    s.add_argument('--loss', type=_nonneg, help='[%%]')
    s.add_argument('--rate', type=_nonneg, help='[Mbit/s], 0 = unlimited')
    s.add_argument('--queue', type=int, help='[packets]')
    s.add_argument('--outage', type=_onoff)
    s.add_argument('--reorder', type=_onoff)
    t = sub.add_parser('trace')
    t.add_argument('file')
    f = sub.add_parser('follow')
    f.add_argument('--map', default=os.path.join(WS, 'config', 'link_map_corridor.yaml'))
    r = sub.add_parser('robot')
    r.add_argument('--uncapped', action='store_true', help='without the CPU cap (testbed.robot_cpu)')
    r.add_argument('command', nargs=argparse.REMAINDER, help='-- CMD [ARGS...]')
    c = sub.add_parser('cpu')
    c.add_argument('--json', action='store_true')
    return ap


def overrides(name):
    return {} if not name else {'name': name, 'robot.namespace': f'{name}-robot', 'cloud.namespace': f'{name}-cloud',
                                'robot.device': f'{name}-r'[:15], 'cloud.device': f'{name}-c'[:15]}


def print_status(st) -> None:
    if not st.get('running'):
        ns = st.get('namespaces', [])
        print('testbed: down' + (f" (leftover namespaces: {', '.join(ns)}; run testbed.sh down)" if ns else ''))
        return
    print(f"testbed '{st['name']}': up for {st['uptime']:.0f} s, supervisor pid {st['pid']}, emulator pid "
          f"{st['emulator_pid']}")
    for side in ('robot', 'cloud'):
        s = st[side]
        print(f"  {side:5s} namespace {s['namespace']:12s} {s['device']:12s} {s['address']}")
    for d, arrow in (('up', 'robot -> cloud'), ('down', 'cloud -> robot')):
        c, n = st[d]['conditions'], st[d]['counters']
        cond = (f"delay {c['delay']:g} ms, jitter {c['jitter']:g} ms, loss {100 * c['loss']:g} %, rate "
                f"{'unlimited' if not c['rate'] else str(c['rate']) + ' Mbit/s'}, queue {c['queue']}"
                + (', OUTAGE' if c['outage'] else ''))
        print(f"  {d:4s} ({arrow}): {cond}")
        print(f"        packets {n['offered']} offered, {n['delivered']} delivered, {n['dropped_loss']} lost, "
              f"{n['dropped_queue']} queue drops, {st[d]['in_flight']} in flight")


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    from cnr_testbed.api import Testbed, TestbedError
    try:
        tb = Testbed(args.config, overrides(args.name))
        if args.cmd == 'up':
            print_status(tb.up())
        elif args.cmd == 'down':
            tb.down()
            print('testbed: down (namespaces, devices and processes removed)')
        elif args.cmd == 'status':
            st = tb.status()
            print(json.dumps(st, indent=1)) if args.json else print_status(st)
        elif args.cmd == 'set':
            changes = {k: getattr(args, k) for k in ('delay', 'jitter', 'rate', 'queue', 'outage', 'reorder')
                       if getattr(args, k) is not None}
            if args.loss is not None:
                if args.loss > 100:
                    raise TestbedError(f'--loss must be a percentage 0..100, got {args.loss}')
                changes['loss'] = args.loss / 100.0
            if not changes:
                raise TestbedError('nothing to set (see --help)')
            print_status(dict(running=True, **tb.set(args.dir, **changes)))
        elif args.cmd == 'trace':
            from cnr_testbed.core.config import load_trace
            steps = load_trace(args.file)
            t0 = time.monotonic()
            for st in steps:
                time.sleep(max(0.0, t0 + st.time - time.monotonic()))
                tb.set(st.direction, **st.changes)
                print(f'[{st.time:8.2f} s] {st.direction}: ' + ', '.join(f'{k}={v}' for k, v in st.changes.items()),
                      flush=True)
        elif args.cmd == 'follow':
            from cnr_testbed.follower import follow
            follow(tb, args.map)
        elif args.cmd == 'robot':
            from cnr_testbed.cpucap import run_argv
            command = args.command[1:] if args.command[:1] == ['--'] else args.command
            if not command:
                raise TestbedError('robot needs a command: testbed.sh robot -- CMD [ARGS...]')
            argv = ['ip', 'netns', 'exec', tb.namespace('robot'), *command]
            argv = argv if args.uncapped else run_argv(argv, tb.robot_cgroup, tb.config_path)
            os.execvp(argv[0], argv)
        elif args.cmd == 'cpu':
            from cnr_testbed.cpucap import main as cpucap_main
            return cpucap_main(['--config', tb.config_path, 'status', '--name', tb.robot_cgroup]
                               + (['--json'] if args.json else []))
    except ConfigError as exc:
        print(f'testbed.sh: {exc}', file=sys.stderr)
        return 2
    except (TestbedError, RuntimeError, OSError, ValueError) as exc:
        if isinstance(exc, (ConnectionRefusedError, FileNotFoundError)):
            exc = 'the testbed is not up (testbed.sh up)'
        print(f'testbed.sh: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
