"""Testbed benchmark: added RTT versus the setting, shaped and unshaped throughput (needs root).

    launch_scripts/bench_testbed.sh [--out DIR]

Writes docs/results/testbed/ (or DIR): README.md and testbed.tsv.

Added RTT: ping (50 probes, 20 ms apart) from the robot namespace to the cloud with the one-way delay set
to half the RTT on both directions, minus the RTT at 0 ms. Throughput: iperf3 (TCP, 5 s) robot -> cloud.
Targets: added RTT within +/-1 ms from 0 to 200 ms; throughput within 5 % of 1-50 Mbit/s;
>= 100 Mbit/s unshaped.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import time
from typing import List, Optional

from cnr_benchmarks import cli, report, results
from cnr_testbed.api import Testbed


def ping_avg(tb: Testbed, count: int = 50) -> float:
    r = tb.exec_in('robot', ['ping', '-q', '-c', str(count), '-i', '0.02', '-W', '2', tb.cloud_address],
                   capture_output=True, text=True, timeout=120)
    m = re.search(r'= [\d.]+/([\d.]+)/', r.stdout)
    if not m:
        raise RuntimeError(f'ping failed: {r.stdout} {r.stderr}')
    return float(m.group(1))


def iperf(tb: Testbed, seconds: float = 5.0) -> float:
    server = tb.popen_in('cloud', ['iperf3', '-s', '-1', '-B', tb.cloud_address], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    try:
        time.sleep(0.5)
        r = tb.exec_in('robot', ['iperf3', '-J', '-c', tb.cloud_address, '-t', str(seconds)], capture_output=True,
                       text=True, timeout=seconds + 30)
        data = json.loads(r.stdout)
        return data['end']['sum_received']['bits_per_second'] / 1e6
    finally:
        server.kill()
        server.wait()


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('bench_testbed.sh', __doc__)
    ap.add_argument('--out', default=results.results_dir('testbed'), help="the page's folder (default %(default)s)")
    args = ap.parse_args(argv)
    cli.require_root(ap.prog, 'network namespaces and TUN devices')
    rows = []
    name = f'tbb{os.getpid() % 10000}'
    tb = Testbed(os.path.join(results.WS, 'config', 'testbed.yaml'),
                 {'name': name, 'robot.namespace': f'{name}-robot', 'cloud.namespace': f'{name}-cloud',
                  'robot.device': f'{name}-r', 'cloud.device': f'{name}-c'})
    with tb:
        base = ping_avg(tb)
        print(f'base RTT {base:.3f} ms', flush=True)
        for rtt in (0, 20, 50, 100, 150, 200):
            tb.set('both', delay=rtt / 2.0)
            avg = ping_avg(tb)
            added = avg - base
            ok = abs(added - rtt) <= 1.0
            rows.append(('rtt', rtt, 'ms', round(added, 3), 'within 1 ms' if ok else 'OFF'))
            print(f'RTT setting {rtt:4d} ms: measured added RTT {added:8.3f} ms ({"ok" if ok else "OFF"})', flush=True)
        tb.set('both', delay=0.0)
        for rate in (1, 10, 50, 0):
            tb.set('both', rate=float(rate), queue=200)
            mbit = iperf(tb)
            if rate:
                ok = abs(mbit - rate) / rate <= 0.05
                rows.append(('throughput', rate, 'Mbit/s', round(mbit, 2), 'within 5 %' if ok else 'OFF'))
            else:
                ok = mbit >= 100
                rows.append(('throughput', 'unshaped', 'Mbit/s', round(mbit, 1), '>= 100' if ok else 'BELOW'))
            print(f'rate {rate or "unshaped"}: {mbit:.2f} Mbit/s ({"ok" if ok else "OFF"})', flush=True)
    os.makedirs(args.out, exist_ok=True)
    results.write_tsv(os.path.join(args.out, 'testbed.tsv'), ['quantity', 'setting', 'unit', 'measured', 'check'],
                      rows)
    table = report.markdown_table(['quantity', 'setting', 'measured', 'check'],
                                  [[q, f'{s} {u}', f'{m} {u}', c] for q, s, u, m, c in rows])
    print(results.write_page(args.out, 'Link emulator', 'thesis Appendix I: `tc` between robot and cloud',
                             f'{table}\n\nbase RTT through the emulator: {base:.3f} ms; rows in testbed.tsv.\n',
                             cli.command(ap, argv)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
