"""Benchmark of the robot's CPU cap (needs root): achieved slowdown and scheduling jitter.

    launch_scripts/bench_cpucap.sh [--out DIR] [--repeats N] [--seconds S]

Measures the robot's CPU cap (config/testbed.yaml testbed.robot_cpu). Needs root; about a minute. Writes the page
docs/results/cpucap/README.md (or DIR/README.md); the raw figures go to bench_results/cpucap/cpucap.json.

(a) Cap and slowdown: the CPU share a hog in the cgroup gets (usage over wall time) against the configured
limit (``testbed.robot_cpu``); then a CPU-bound Python loop (fixed work, timed inside the child, interpreter
start excluded) run uncapped and inside the cgroup, alternately, ``repeats`` times. Slowdown = median wall
time inside over median wall time outside, and over median CPU time outside (robust to other jobs slowing
the uncapped run); CPU inflation = CPU time inside over CPU time outside (caches refilled after every
throttled period).

(b) Jitter: a 10 ms periodic loop (``time.sleep`` to the next deadline, as ``rospy.Rate``) inside the cgroup
while a CPU hog in the same cgroup uses up its quota, for several CFS periods at the same CPU share; the
lateness of each wake-up (median, p95, max over every run). Periods whose quota would be below the kernel's
1 ms minimum are listed as not settable. The baseline is the same loop uncapped and without the hog.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Optional, Tuple

from cnr_benchmarks import cli, results
from cnr_benchmarks.core.stats import percentile
from cnr_testbed import cpucap
from cnr_testbed.core import cpucap as core
from cnr_testbed.core.config import load_testbed

WORK = ('import time\nt, c = time.perf_counter(), time.process_time()\nx = 0\nfor i in range({n}): x += i * i\n'
        'print(time.perf_counter() - t, time.process_time() - c)\n')
HOG = 'while True: pass\n'
SLEEPER = '''import json, sys, time
period, n, warmup = 0.01, int(sys.argv[1]), 20
nxt = time.monotonic() + period
late = []
for i in range(n + warmup):
    d = nxt - time.monotonic()
    if d > 0:
        time.sleep(d)
    now = time.monotonic()
    if i >= warmup:
        late.append(now - nxt)
    nxt += period
    if now - nxt > period:          # fell behind by more than a period: restart the schedule (rospy.Rate)
        nxt = now + period
print(json.dumps(late))
'''
PERIODS_US = (1000, 5000, 10000, 20000, 50000, 100000)   # and the shortest settable one


def _python(code: str, *args: str, cgroup: Optional[str] = None) -> List[str]:
    argv = [sys.executable, '-c', code, *args]
    return cpucap.run_argv(argv, cgroup) if cgroup else argv


def timed_work(n: int, cgroup: Optional[str]) -> Tuple[float, float]:
    """(wall, CPU) seconds of ``n`` iterations of a Python loop."""
    r = subprocess.run(_python(WORK.format(n=n), cgroup=cgroup), capture_output=True, text=True, check=True,
                       timeout=300)
    wall, cpu = r.stdout.split()[-2:]
    return float(wall), float(cpu)


def hog_share(cg: cpucap.CpuCgroup, seconds: float = 3.0) -> float:
    """CPUs' worth a CPU hog in ``cg`` gets (usage over wall time)."""
    hog = subprocess.Popen(_python(HOG, cgroup=cg.name), stdout=subprocess.DEVNULL)
    try:
        time.sleep(0.5)
        u0, t0 = cg.usage_seconds(), time.monotonic()
        time.sleep(seconds)
        return (cg.usage_seconds() - u0) / (time.monotonic() - t0)
    finally:
        hog.kill()
        hog.wait()


def lateness(n: int, cgroup: Optional[str], hog: bool) -> List[float]:
    procs = []
    try:
        if hog:
            procs.append(subprocess.Popen(_python(HOG, cgroup=cgroup), stdout=subprocess.DEVNULL))
            time.sleep(0.3)
        r = subprocess.run(_python(SLEEPER, str(n), cgroup=cgroup), capture_output=True, text=True, check=True,
                           timeout=120)
        return json.loads(r.stdout)
    finally:
        for p in procs:
            p.kill()
            p.wait()


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('bench_cpucap.sh', __doc__)
    ap.add_argument('--out', default=results.results_dir('cpucap'), help='the page\'s folder (default %(default)s)')
    ap.add_argument('--config', default=cpucap.CONFIG)
    ap.add_argument('--repeats', type=cli.positive_int, default=3)
    ap.add_argument('--seconds', type=float, default=3.0, help='per jitter run')
    args = ap.parse_args(argv)
    cli.require_root(ap.prog, 'cgroups')
    cfg = load_testbed(args.config).robot_cpu
    layout = cpucap.detect()
    load0 = open('/proc/loadavg').read().split()[:3]
    name = f'cnr_bench_{os.getpid()}'
    cg = cpucap.CpuCgroup(layout, name)
    out: Dict = dict(slowdown=cfg.slowdown, cpus=cfg.cpus, period_us=cfg.period_us, cgroup_version=layout.version)
    try:
        # (a) cap and slowdown
        cg.create(cfg.cpus, cfg.period_us)
        out['share'] = hog_share(cg)
        print(f"hog in the cgroup: {out['share']:.4f} CPU (limit {cfg.cpus:.4f})", flush=True)
        n = 3_000_000
        outside, inside = [], []
        for _ in range(args.repeats):
            outside.append(timed_work(n, None))
            inside.append(timed_work(n, name))
            print(f'loop of {n} iterations: uncapped {outside[-1][0]:.3f} s ({outside[-1][1]:.3f} s CPU), capped '
                  f'{inside[-1][0]:.3f} s ({inside[-1][1]:.3f} s CPU)', flush=True)
        med = {k: statistics.median(x[j] for x in v) for k, v in (('out', outside), ('in', inside))
               for j, k in ((0, k + '_wall'), (1, k + '_cpu'))}
        out['work'] = dict(iterations=n, outside=outside, inside=inside,
                           ratio_wall=med['in_wall'] / med['out_wall'], ratio_cpu=med['in_wall'] / med['out_cpu'],
                           runs_wall=[i[0] / o[0] for i, o in zip(inside, outside)],
                           runs_cpu=[i[0] / o[1] for i, o in zip(inside, outside)],
                           inflation=med['in_cpu'] / med['out_cpu'])
        cg.remove()
        # (b) jitter
        wakeups = int(args.seconds / 0.01)
        rows = []
        base = [x for _ in range(2) for x in lateness(wakeups, None, hog=False)]
        rows.append(dict(setting='uncapped, no hog', late=base))
        for period in sorted(set(PERIODS_US) | {core.shortest_period_us(cfg.cpus)}):
            try:
                core.quota_us(cfg.cpus, period)
            except ValueError as exc:
                rows.append(dict(setting=f'period {period} us', period_us=period, error=str(exc)))
                continue
            late: List[float] = []
            throttled = []
            for _ in range(2):
                cg.create(cfg.cpus, period)
                late += lateness(wakeups, name, hog=True)
                t = cg.throttling()
                throttled.append(t.throttled_fraction)
                cg.remove(kill=True)
            rows.append(dict(setting=f'period {period} us', period_us=period, late=late, throttled=throttled))
            print(f"period {period:6d} us: lateness median {1e3 * statistics.median(late):.2f} ms, p95 "
                  f"{1e3 * percentile(late, 95):.2f} ms, max {1e3 * max(late):.2f} ms", flush=True)
        out['jitter'] = rows
    finally:
        if cg.exists():
            cg.remove(kill=True)
    out['loadavg'] = [load0, open('/proc/loadavg').read().split()[:3]]
    results.save_json(os.path.join(results.scratch_dir('cpucap'), 'cpucap.json'), out)
    print(results.write_page(args.out, "The robot's CPU cap", 'thesis Table 3-1, Appendix IV', report(out),
                             cli.command(ap, argv)))
    return 0


def report(out: Dict) -> str:
    w = out['work']

    def span(values: List[float]) -> str:
        return f'{min(values):.3f}-{max(values):.3f}'

    lines = [f"cgroup v{out['cgroup_version']}: {out['cpus']:.4g} CPU (slowdown {out['slowdown']:g}), period "
             f"{out['period_us']} us.", '',
             '## (a) Cap and slowdown of a CPU-bound Python loop', '',
             f"CPU hog in the cgroup: {out['share']:.4f} CPU (limit {out['cpus']:.4f}).", '',
             f"{w['iterations']} iterations, {len(w['inside'])} alternating runs: uncapped "
             f"{span([x[0] for x in w['outside']])} s wall ({span([x[1] for x in w['outside']])} s CPU), capped "
             f"{span([x[0] for x in w['inside']])} s wall ({span([x[1] for x in w['inside']])} s CPU).", '',
             '| slowdown (configured ' + f"{out['slowdown']:g}" + ') | median | per run |', '|---|---|---|',
             f"| capped wall / uncapped wall | {w['ratio_wall']:.2f} | "
             f"{min(w['runs_wall']):.2f}-{max(w['runs_wall']):.2f} |",
             f"| capped wall / uncapped CPU | {w['ratio_cpu']:.2f} | "
             f"{min(w['runs_cpu']):.2f}-{max(w['runs_cpu']):.2f} |",
             f"| CPU inflation (capped CPU / uncapped CPU) | {w['inflation']:.2f} | |", '',
             '## (b) Wake-up lateness of a 10 ms periodic loop, CPU hog in the same cgroup', '',
             '| setting | quota | median | p95 | max | periods throttled |', '|---|---|---|---|---|---|']
    for r in out['jitter']:
        if 'error' in r:
            lines.append(f"| {r['setting']} | not settable | | | | {r['error']} |")
            continue
        late = r['late']
        quota = f"{round(out['cpus'] * r['period_us'])} us" if 'period_us' in r else '-'
        thr = ', '.join(f'{100 * t:.0f} %' for t in r.get('throttled', [])) or '-'
        lines.append(f"| {r['setting']} | {quota} | {1e3 * statistics.median(late):.2f} ms | "
                     f"{1e3 * percentile(late, 95):.2f} ms | {1e3 * max(late):.2f} ms | {thr} |")
    lines += ['', f"Load average before/after: {' '.join(out['loadavg'][0])} / {' '.join(out['loadavg'][1])}.", '']
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())
