"""Table 4-2 / Appendix III: start-up time of the navigation node on the cloud host, single vs multi master.

    launch_scripts/bench_startup.sh [--rtts 0,20,50,100,120,140] [--runs 5] [--modes SM,MM] [--out DIR]

Start-up time of the navigation node (move_base) on the cloud host, from process start until its action server is
usable from the robot's master, with a single master (the robot's) versus one master per host joined by
multimaster_bridge, 5 runs per link RTT. Needs root. The single-master runs dominate: about 30 minutes in all.

The simulated TurtleBot (simulator + map_server) runs on the robot's master. move_base (cnr_navigation) is
started on the cloud host:

* ``SM`` (single master): its ROS_MASTER_URI is the robot's master, across the emulated link, so each of its
  ~380 parameter calls and ~60 registrations pays the link's round trip, one call after the other;
* ``MM`` (multi-master): it uses the cloud host's own master; multimaster_bridge (config/bridge_*.yaml allow
  lists) makes its topics and services known on the robot's master.

Start-up = process start until move_base's action server (its five action topics) is registered on the
**robot's** master, i.e. usable by the robot; for MM this includes the bridge's sync. The parameters are put
on the master move_base uses before each run (as roslaunch would, not timed). Writes docs/results/startup/ (or
DIR): ``startup.tsv`` (every run), ``README.md`` (thesis beside ours) and ``startup.png``; the rows as measured go
to bench_results/startup/startup.tsv.
"""
from __future__ import annotations

import os
import sys
import time
import xmlrpc.client
from typing import Dict, List

import yaml

from cnr_benchmarks import cli, report, results
from cnr_benchmarks.core.stats import summarize
from cnr_harness import wait_until

COLUMNS = ['mode', 'link_rtt_ms', 'run', 'startup_ms']
# thesis Appendix III, averages in ms (5 runs each); std.dev where Table 4-2 gives it
THESIS_SM = {0: 13414.0, 20: 45332.0, 50: 95688.0, 100: 174452.0, 120: 200556.0, 140: 230206.0}
THESIS_MM = {0: 5350.0, 20: 5422.0, 50: 5350.0, 100: 5634.0, 120: 5986.0, 140: 6112.0}
THESIS_SD = {('SM', 0): 854.01, ('SM', 50): 1555.95, ('SM', 140): 1556.01,
             ('MM', 0): 236.11, ('MM', 50): 182.21, ('MM', 140): 246.82}
ACTION_PUBS = ('status', 'result', 'feedback')
ACTION_SUBS = ('goal', 'cancel')
MOVE_BASE = ['rosrun', 'cnr_navigation', 'move_base', '__name:=move_base', 'cmd_vel:=mobile_base/commands/velocity']


def _bridge_settings() -> Dict:
    with open(os.path.join(report.WS, 'config', 'bridge_robot.yaml')) as f:
        cfg = yaml.safe_load(f)
    return {k: cfg[k] for k in ('allow_topics', 'deny_topics', 'allow_services', 'deny_services') if k in cfg}


def action_ready(side, node: str) -> bool:
    pubs, subs, _ = side.call('getSystemState')
    pubs, subs = dict(pubs), dict(subs)
    return (all(node in pubs.get(f'/move_base/{t}', []) for t in ACTION_PUBS)
            and all(node in subs.get(f'/move_base/{t}', []) for t in ACTION_SUBS))


def publishes_clock(side) -> bool:
    return '/clock' in {t for t, _ in side.call('getSystemState')[0]}


def node_gone(side, node: str) -> bool:
    pubs, subs, srvs = side.call('getSystemState')
    return not any(node in nodes for _, nodes in pubs + subs + srvs)


def cleanup_node(side, node: str) -> int:
    """Remove what a dead node left registered, as ``rosnode cleanup`` does; returns how many entries."""
    from cnr_testbed import netns
    pubs, subs, srvs = side.call('getSystemState')
    with netns.inside(side.namespace):
        master = xmlrpc.client.ServerProxy(side.master_uri)
        code, _, api = master.lookupNode('/bench', node)
        if code != 1:
            return 0
        multi = xmlrpc.client.MultiCall(master)
        n = 0
        for topic, nodes in pubs:
            if node in nodes:
                multi.unregisterPublisher(node, topic, api)
                n += 1
        for topic, nodes in subs:
            if node in nodes:
                multi.unregisterSubscriber(node, topic, api)
                n += 1
        for service, nodes in srvs:
            if node in nodes:
                code, _, service_api = master.lookupService('/bench', service)
                if code == 1:
                    multi.unregisterService(node, service, service_api)
                    n += 1
        if n:
            multi()
    return n


def load_params(side) -> None:
    from cnr_benchmarks.startup_audit import load_navigation_params
    from cnr_testbed import netns
    with netns.inside(side.namespace):
        load_navigation_params(xmlrpc.client.ServerProxy(side.master_uri))


class Setup:
    """Masters, simulator and (MM) bridges of one mode, kept up across link settings and runs."""

    def __init__(self, tb, mode: str, work: str, secret: str) -> None:
        from cnr_testbed.rosside import RosSide, start_bridge
        self.mode = mode
        self.robot = RosSide(tb, 'robot', 'robot', 11411, log_dir=work)
        self.cloud_master = RosSide(tb, 'cloud', 'cloud', 11411, log_dir=work) if mode == 'MM' else None
        self.cloud = RosSide(tb, 'cloud', 'robot' if mode == 'SM' else 'cloud', 11411, log_dir=work)
        self.robot.start_master(use_sim_time=True)
        sim = self.robot.run(['roslaunch', 'cnr_sim', 'simulator.launch', 'real_time_factor:=1'], 'simulator')
        wait_until(lambda: publishes_clock(self.robot), 60, 'the simulator', sim)
        self.node = '/move_base'
        if mode == 'MM':
            self.cloud_master.start_master(use_sim_time=True)
            start_bridge(self.robot, self.cloud_master, secret, **_bridge_settings())
            start_bridge(self.cloud_master, self.robot, secret, **_bridge_settings())
            self.node = '/cloud/move_base'
            wait_until(lambda: publishes_clock(self.cloud_master), 60, 'the bridges to sync /clock to the cloud')

    @property
    def nav_master(self):
        return self.cloud_master if self.mode == 'MM' else self.robot

    def run_once(self, timeout: float) -> float:
        load_params(self.nav_master)
        t0 = time.monotonic()
        proc = self.cloud.run(MOVE_BASE, f'move_base_{self.mode}')
        try:
            wait_until(lambda: action_ready(self.robot, self.node), timeout, 'the move_base action server', proc,
                       interval=0.02)
            return time.monotonic() - t0
        finally:
            t_stop = time.monotonic()
            self.cloud.stop_proc(proc)   # SIGINT; rospy unregisters (across the link for SM)
            self.last_stop = (time.monotonic() - t_stop, proc.returncode)
            # a node stopped early in its start-up may leave registrations behind: clean up like rosnode cleanup
            stale = cleanup_node(self.nav_master, '/move_base')
            if stale:
                report.progress(f'    (removed {stale} registrations the stopped move_base left behind; it took '
                                f'{self.last_stop[0]:.1f} s to stop, exit status {self.last_stop[1]})')
            wait_until(lambda: node_gone(self.robot, self.node) and (
                self.cloud_master is None or node_gone(self.cloud_master, '/move_base')), 60,
                f'{self.node} to leave the masters after it stopped', interval=0.1)

    def stop(self) -> None:
        for side in (self.cloud, self.cloud_master, self.robot):
            if side is not None:
                side.stop()


def write_outputs(rows: List[Dict], rtts: List[float], out_dir: str, command: str) -> str:
    """startup.tsv, startup.png and the page README.md in ``out_dir``; returns the page."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    groups = report.group(rows, 'mode', 'link_rtt_ms')
    md = ['Measured with `launch_scripts/bench_startup.sh`: process start until the `move_base` action server is '
          'registered on the robot\'s master. Mean ± std.dev (std.err) over the runs, in ms; the thesis\'s '
          'averages (5 runs, TurtleBot laptop + cloud VM, `tc` delay) beside ours.', '']
    header = ['link RTT (ms)', 'SM ours', 'SM thesis', 'MM ours', 'MM thesis']
    table = []

    def cell(mode, r):
        vals = [x['startup_ms'] for x in groups.get((mode, r), [])]
        if not vals:
            return '–'
        s = summarize(vals)
        return f'{s.average:.0f} ± {s.std_dev:.0f} ({s.std_err:.0f}), n={s.sample_size}'

    def thesis(mode, r):
        avg = (THESIS_SM if mode == 'SM' else THESIS_MM).get(int(r))
        if avg is None:
            return '–'
        sd = THESIS_SD.get((mode, int(r)))
        return f'{avg:.0f}' + (f' ± {sd:.0f}' if sd else '')

    for r in rtts:
        table.append([f'{r:g}', cell('SM', r), thesis('SM', r), cell('MM', r), thesis('MM', r)])
    md += [report.markdown_table(header, table), '']
    mm0 = [x['startup_ms'] for x in groups.get(('MM', 0.0), [])]
    mm_max = [x['startup_ms'] for x in groups.get(('MM', max(rtts)), [])]
    if mm0 and mm_max and max(rtts) > 0:
        ratio = summarize(mm_max).average / summarize(mm0).average
        md += [f'Multi-master at {max(rtts):g} ms / at 0 ms: **{ratio:.2f}x** (target ≤ 1.10x; thesis '
               f'{THESIS_MM[140] / THESIS_MM[0]:.2f}x at 140 ms).', '']
    sm0 = [x['startup_ms'] for x in groups.get(('SM', 0.0), [])]
    sm_max = [x['startup_ms'] for x in groups.get(('SM', max(rtts)), [])]
    if sm0 and sm_max:
        md += [f'Single master at {max(rtts):g} ms / at 0 ms: {summarize(sm_max).average / summarize(sm0).average:.1f}x '
               f'(thesis {THESIS_SM[140] / THESIS_SM[0]:.1f}x at 140 ms).', '']
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for mode, color in (('SM', 'tab:red'), ('MM', 'tab:blue')):
        xs = [r for r in rtts if (mode, r) in groups]
        if xs:
            stats = [summarize([x['startup_ms'] / 1000 for x in groups[(mode, r)]]) for r in xs]
            ax.errorbar(xs, [s.average for s in stats], yerr=[s.std_dev for s in stats], marker='o', capsize=3,
                        color=color, label=f'{mode} (ours)')
        th = THESIS_SM if mode == 'SM' else THESIS_MM
        ax.plot(list(th), [v / 1000 for v in th.values()], linestyle='--', marker='x', color=color,
                alpha=0.6, label=f'{mode} (thesis)')
    ax.set_xlabel('link RTT (ms)')
    ax.set_ylabel('move_base start-up (s)')
    ax.set_yscale('log')
    ax.grid(alpha=0.3, which='both')
    ax.legend()
    fig.tight_layout()
    md += ['![start-up time](startup.png)', '']
    return results.write_page(out_dir, 'move_base start-up on the cloud, single vs multi-master',
                              'thesis Table 4-2, Appendix III', '\n'.join(md), command, {'startup.png': fig},
                              {'startup.tsv': (COLUMNS, rows)})


def main(argv=None) -> int:
    ap = cli.Parser('bench_startup.sh', __doc__)
    report.add_common_arguments(ap, '0,20,50,100,120,140', 'startup')
    ap.add_argument('--runs', type=int, default=5)
    ap.add_argument('--modes', default='SM,MM')
    ap.add_argument('--timeout', type=float, default=900.0, help='seconds per run before giving up')
    args = ap.parse_args(argv)
    modes = args.modes.split(',')
    if any(m not in ('SM', 'MM') for m in modes) or args.runs < 1:
        ap.error(f'--modes {args.modes} (SM, MM) or --runs {args.runs} < 1')
    cli.require_root(ap.prog, "the testbed's network namespaces and TUN devices")
    rows: List[Dict] = []
    with report.BenchRun('bench_startup', args, 'startup', 'startup.tsv', COLUMNS) as bench:
        tb = bench.testbed
        for mode in modes:
            report.progress(f'{mode}: bringing up masters, simulator' + (' and bridges' if mode == 'MM' else ''))
            tb.set('both', delay=0.0, jitter=0.0, loss=0.0, outage=False)
            setup = Setup(tb, mode, bench.work, bench.secret)
            try:
                for r in bench.rtts:
                    tb.set('both', delay=r / 2.0)
                    for run in range(1, args.runs + 1):
                        try:
                            t = setup.run_once(args.timeout) * 1000.0
                        except RuntimeError as exc:
                            report.progress(f'  {mode} {r:5.0f} ms run {run}: FAILED: {exc}')
                            continue
                        bench.log.row(mode=mode, link_rtt_ms=r, run=run, startup_ms=t)
                        rows.append(dict(mode=mode, link_rtt_ms=r, run=run, startup_ms=t))
                        report.progress(f'  {mode} {r:5.0f} ms run {run}/{args.runs}: {t:9.0f} ms')
            finally:
                setup.stop()
    print(write_outputs(rows, bench.rtts, args.out, cli.command(ap, argv)))
    bench.say_written(args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
