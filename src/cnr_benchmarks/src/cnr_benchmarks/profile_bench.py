"""Accuracy and cost of network_monitor's profile on the testbed (needs root).

    launch_scripts/bench_profile.sh [--quick] [--reps N (default 2)] [--probe-method {iperf3,train}] [--name bp]
        [--out DIR] [--config testbed.yaml]

For each link RTT (0, 20, 50, 100, 150 ms, as two one-way halves) x rate (1, 3.4, 10, 50 Mbit/s both ways), after an
unshaped 0 ms baseline: the profile's RTT vs set + baseline (target +/-2 ms), the probe's A_bw vs the rate (+/-10 %),
the passive estimate 10 s after the probe under 0.5 x rate of background load (+/-20 %), and the probe's cost
(bytes on the link, seconds per ~profile_now). About 15 minutes (--quick: 2 RTT x 2 rates, 1 repetition, about
2 minutes).

The active A_bw probe (``--probe-method``, default: ``probe_method`` in config/network_monitor.yaml):

* ``iperf3``: a TCP stream from the robot to the cloud's iperf3 server, ``probe_seconds`` measured after
  ``probe_omit`` s of slow start, paced to at most ``probe_bytes`` (about 4 s of the link at full rate).
* ``train``: a UDP packet train of ``train_packets`` x ``train_packet_bytes`` (88 KB) sent back-to-back from the
  robot to the cloud's train responder (``train_server: true`` on the cloud), A_bw from the dispersion of its
  arrivals (milliseconds to about a second of the link).

Brings up its own testbed instance (``--name``: namespaces NAME-robot / NAME-cloud, never the lead's ``cnr``),
a master on each host joined by multimaster_bridge (``/network_monitor/*`` and the load topic allowed) and a
network_monitor on each (config/network_monitor.yaml; overlays: the instance's addresses, the cloud's
name/peer, ``probe_interval: 0`` so no periodic probe disturbs the measurements, ``probe_method`` on both and,
with ``train``, the cloud's ``train_server: true``). The measuring node (:mod:`cnr_benchmarks.profile_worker`)
runs on the robot; the first cell is the unshaped, undelayed baseline. Writes docs/results/profile/
(``--probe-method train``: docs/results/profile_train/; or DIR): ``profile.tsv`` (every repetition) and
``README.md`` (probe method, table, date, duration, load); the rows as measured go to
bench_results/profile/profile.tsv (bench_results/profile_train/ for the train).
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import tempfile
import time
from typing import Dict, List, Optional, Tuple

from cnr_benchmarks import cli, report, results
from cnr_params import Section, exit_on_config_error

RTTS = (0, 20, 50, 100, 150)          # ms, set as two one-way halves
RATES = (1, 3.4, 10, 50)              # Mbit/s on both directions
QUICK_RTTS = (0, 150)
QUICK_RATES = (1, 50)
REPS = 2
LOAD_FRACTION = 0.5                   # background load during the passive phase, of the set rate
LOAD_HZ = 20.0                        # its messages per second
PASSIVE_AGE = 10.0                    # s after the probe the passive estimate is read
BRIDGE_SETTINGS = dict(allow_topics=['/network_monitor/*', '/bench_profile/*'])
EXPERIMENTS = {'iperf3': 'profile', 'train': 'profile_train'}   # probe method -> docs/results/<experiment>
METHOD_TITLES = {'iperf3': 'iperf3 probe', 'train': 'packet-train probe'}

HELP_GRID = (f'Grid: RTT {", ".join(map(str, RTTS))} ms x rate {", ".join(map(str, RATES))} Mbit/s, {REPS} '
             f'repetitions (--quick: RTT {", ".join(map(str, QUICK_RTTS))} ms x rate '
             f'{", ".join(map(str, QUICK_RATES))} Mbit/s, 1 repetition), after an unshaped 0 ms baseline cell. '
             f'Passive phase: {LOAD_FRACTION:g} x rate of background load in {LOAD_HZ:g} messages/s, estimate '
             f'read {PASSIVE_AGE:g} s after the probe.')


def cells(quick: bool) -> List[Tuple[float, float]]:
    rtts, rates = (QUICK_RTTS, QUICK_RATES) if quick else (RTTS, RATES)
    return [(0.0, 0.0)] + [(float(r), float(b)) for r in rtts for b in rates]


def monitor_config_path(ws: str = report.WS) -> str:
    return os.path.join(ws, 'config', 'network_monitor.yaml')


def configured_probe_method(ws: str = report.WS) -> str:
    """``probe_method`` of config/network_monitor.yaml (a ConfigError naming the file and field if missing)."""
    from network_monitor.core.config import PROBE_METHODS
    return Section.from_file(monitor_config_path(ws)).string('probe_method', choices=PROBE_METHODS)


def monitor_overlays(probe_method: str, robot_address: str, cloud_address: str) -> Dict[str, dict]:
    """Each host's overlay over config/network_monitor.yaml: the addresses, the cloud's name/peer, no periodic
    probe, the probe method on both, and with ``train`` the cloud's train responder (the robot probes the cloud)."""
    common = dict(probe_interval=0.0, probe_method=probe_method)
    cloud = dict(common, name='cloud', peer='robot', peer_address=robot_address)
    if probe_method == 'train':
        cloud['train_server'] = True
    return {'robot': dict(common, peer_address=cloud_address), 'cloud': cloud}


def default_out(probe_method: str) -> str:
    return results.results_dir(EXPERIMENTS[probe_method])


def write_yaml(path: str, data: dict) -> str:
    import yaml
    with open(path, 'w') as f:
        yaml.safe_dump(data, f)
    return path


def follow(proc, printed: int) -> int:
    """Print the lines ``proc`` wrote since ``printed`` characters; returns the new count."""
    text = proc.output()
    end = text.rfind('\n') + 1
    if end > printed:
        sys.stdout.write(text[printed:end])
        sys.stdout.flush()
        return end
    return printed


def measure(args: argparse.Namespace, grid: List[Tuple[float, float]], reps: int, tsv: str, work: str) -> None:
    from cnr_harness import wait_until
    from cnr_testbed.api import Testbed
    from cnr_testbed.cli import overrides
    from cnr_testbed.rosside import RosSide, start_bridge
    tb = Testbed(args.config, overrides(args.name))
    secret = os.path.join(work, 'secret')
    with open(secret, 'w') as f:
        f.write(os.urandom(16).hex())
    robot = cloud = None
    try:
        tb.up()
        report.progress(f"testbed '{args.name}' up: robot {tb.robot_address} ({tb.namespace('robot')}), "
                        f"cloud {tb.cloud_address} ({tb.namespace('cloud')})")
        robot, cloud = RosSide(tb, 'robot', log_dir=work), RosSide(tb, 'cloud', log_dir=work)
        robot.start_master()
        cloud.start_master()
        bridges = [start_bridge(robot, cloud, secret, **BRIDGE_SETTINGS),
                   start_bridge(cloud, robot, secret, **BRIDGE_SETTINGS)]
        wait_until(lambda: 'peer cloud is up' in bridges[0].output() and 'peer robot is up' in bridges[1].output(),
                   60, 'the bridges to see each other')
        overlays = monitor_overlays(args.probe_method, tb.robot_address, tb.cloud_address)
        for side in (robot, cloud):
            path = write_yaml(os.path.join(work, f'network_monitor_{side.side}.yaml'), overlays[side.side])
            side.run(['roslaunch', 'network_monitor', 'network_monitor.launch', f'overlay:={path}'],
                     f'network_monitor_{side.side}')
        cloud.run([sys.executable, '-m', 'cnr_benchmarks.profile_worker', '--sink'], 'sink')
        report.progress(f'masters, bridges, monitors ({args.probe_method} probe) and load sink started; measuring')
        worker = robot.run([sys.executable, '-m', 'cnr_benchmarks.profile_worker',
                            '--testbed-config', args.config, '--testbed-name', args.name,
                            '--cells', ','.join(f'{r:g}:{b:g}' for r, b in grid), '--reps', str(reps),
                            '--out', tsv, '--load-fraction', str(LOAD_FRACTION), '--load-hz', str(LOAD_HZ),
                            '--passive-age', str(PASSIVE_AGE)], 'worker')
        printed = 0
        while worker.poll() is None:
            printed = follow(worker, printed)
            time.sleep(0.5)
        follow(worker, printed)
        if worker.returncode != 0:
            raise RuntimeError(f'the measuring node exited with {worker.returncode} (see {worker.log_path})')
    finally:
        for side in (cloud, robot):
            if side is not None:
                side.stop()
        tb.down()


def probe_description(probe_method: str, monitor: dict) -> str:
    """The probe as the page names it, from config/network_monitor.yaml's values."""
    if probe_method == 'train':
        n, size = monitor['train_packets'], monitor['train_packet_bytes']
        return (f"a UDP packet train of {n} × {size} B = {n * size / 1e3:.0f} KB robot → cloud, A_bw from the "
                f"dispersion of its arrivals at the cloud's responder")
    return (f"iperf3 -t {monitor['probe_seconds']} -O {monitor['probe_omit']}, at most "
            f"{monitor['probe_bytes'] / 1e6:g} MB")


def write_outputs(tsv: str, out_dir: str, command: str, started: datetime.datetime, wall_s: float,
                  machine: str, probe_method: Optional[str] = None) -> str:
    """The page and TSV in ``out_dir``; ``probe_method`` None: config/network_monitor.yaml's."""
    import csv
    from cnr_benchmarks.core import profile as core
    with open(tsv) as f:
        samples = [core.Sample.from_row(row) for row in csv.DictReader(f, delimiter='\t')]
    base = core.baseline_rtt_ms(samples)
    cells_ = core.summarize_cells(samples, base)
    met = core.totals(cells_)
    from cnr_params import load_yaml
    monitor = load_yaml(monitor_config_path())
    method = probe_method if probe_method is not None else configured_probe_method()
    probe = probe_description(method, monitor)
    carried = ('the train and the responder\'s answer' if method == 'train' else 'data and ACKs')
    reps = max((c.reps for c in cells_), default=0)
    md = [f'Probe method: **{method}** ({probe}).', '',
          f'Started {started:%Y-%m-%d %H:%M}, {wall_s / 60:.1f} min, {reps} repetition(s) per cell; {machine}.', '',
          f'Baseline RTT (0 ms set, unshaped; ROS publish/echo across the bridge plus the emulator): '
          f'**{base:.2f} ms**; RTT error = measured − (set + baseline).', '',
          'Values: mean [min, max] over the repetitions. RTT: the profile\'s median over its '
          f"{monitor['window']:g} s echo window on an idle link. A_bw: `~profile_now` with a probe ({probe}, "
          'config/network_monitor.yaml); error against the set rate (the emulator itself delivers about 3.5 % '
          'less, docs/results/testbed). Passive: the profile\'s A_bw '
          f'{PASSIVE_AGE:g} s after the probe with {LOAD_FRACTION:g} × rate of background load (a ROS topic of '
          f'{LOAD_HZ:g} messages/s across the bridge). Probe cost: bytes the emulator delivered in both '
          f'directions during the call ({carried}, plus pings and bridge heartbeats) and the caller\'s wall time.',
          '',
          report.markdown_table(core.TABLE_HEADER, core.table_rows(cells_)), '',
          f"Targets met: RTT ±{core.RTT_TARGET_MS:g} ms in {met['rtt'][0]}/{met['rtt'][1]} cells, "
          f"A_bw ±{core.A_BW_TARGET_PCT:g} % in {met['a_bw'][0]}/{met['a_bw'][1]}, passive "
          f"±{core.PASSIVE_TARGET_PCT:g} % in {met['passive'][0]}/{met['passive'][1]} (every repetition within); "
          f"the delay error within ±{core.RTT_TARGET_MS:g} ms in {met['delay'][0]}/{met['delay'][1]}.", '',
          'Delay error = measured − (set + the RTT measured at 0 ms and the same rate): the RTT error without the '
          'serialisation of the ping and pong segments at the rate (about 2 × 120 bytes, 1.9 ms at 1 Mbit/s), '
          'which is part of the link\'s real RTT but not of the delay set on the emulator.', '']
    return results.write_page(out_dir, f'Network profile accuracy and probe cost ({METHOD_TITLES[method]})',
                              'thesis §4.2.4, Eq. 4-1', '\n'.join(md), command,
                              tables={'profile.tsv': (core.Sample.columns(), [vars(s) for s in samples])})


def machine_note() -> str:
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    return f'{platform.node()}, load average {load}'


def parse_args(argv=None) -> Tuple[argparse.ArgumentParser, argparse.Namespace]:
    """The options; ``--out`` defaults to the probe method's page folder."""
    from network_monitor.core.config import PROBE_METHODS
    configured = configured_probe_method()
    ap = cli.Parser('bench_profile.sh', __doc__, epilog=HELP_GRID)
    ap.add_argument('--quick', action='store_true', help='the reduced grid, 1 repetition')
    ap.add_argument('--reps', type=int, help=f'repetitions per cell (default {REPS}, --quick 1)')
    ap.add_argument('--probe-method', choices=PROBE_METHODS, default=configured,
                    help="the monitors' active A_bw probe (default %(default)s, config/network_monitor.yaml)")
    ap.add_argument('--name', default='bp', help='testbed instance (namespaces NAME-robot, NAME-cloud)')
    ap.add_argument('--out', help="the page's folder (default "
                    + ', '.join(f'{default_out(m)} with {m}' for m in PROBE_METHODS) + ')')
    ap.add_argument('--config', default=os.path.join(report.WS, 'config', 'testbed.yaml'))
    args = ap.parse_args(argv)
    if args.out is None:
        args.out = default_out(args.probe_method)
    reps = args.reps if args.reps is not None else (1 if args.quick else REPS)
    if reps < 1:
        ap.error(f'--reps must be >= 1, got {reps}')
    args.reps = reps
    return ap, args


@exit_on_config_error
def main(argv=None) -> int:
    ap, args = parse_args(argv)
    reps = args.reps
    cli.require_root(ap.prog, "the testbed's network namespaces and TUN devices")
    grid = cells(args.quick)
    # an earlier one kept as profile.prev.tsv
    tsv = os.path.join(results.scratch_dir(EXPERIMENTS[args.probe_method]), 'profile.tsv')
    work = tempfile.mkdtemp(prefix='bench_profile-')
    started, t0 = datetime.datetime.now(), time.monotonic()
    machine = machine_note()
    report.progress(f'bench_profile: {len(grid)} cells x {reps} repetition(s), {args.probe_method} probe; node logs '
                    f'in {work}')
    measure(args, grid, reps, tsv, work)
    wall = time.monotonic() - t0
    print(write_outputs(tsv, args.out, cli.command(ap, argv), started, wall, machine, args.probe_method))
    print(f'wrote {os.path.join(args.out, "README.md")} and profile.tsv in {wall / 60:.1f} min (rows as measured in '
          f'{tsv})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
