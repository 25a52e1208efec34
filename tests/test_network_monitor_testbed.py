"""network_monitor's profile on the testbed (root): within tolerance at one setting (150 ms RTT, 50 Mbit/s).

Runs bench_profile's reduced grid (``python3 -m cnr_benchmarks.profile_bench --quick``: two masters, bridges and
a monitor per host on a testbed instance of its own) and checks the 150 ms x 50 Mbit/s cell against the
targets: RTT within 2 ms of the set RTT plus the unshaped baseline, A_bw within 10 %, the passive
estimate within 20 %. About two minutes.
"""
import csv
import os
import subprocess

import pytest

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='needs root (network namespaces, TUN devices)')


def test_profile_within_tolerance_at_150_ms_50_mbit(tmp_path):
    out = subprocess.run(['/usr/bin/python3', '-m', 'cnr_benchmarks.profile_bench', '--quick', '--name', 'nmt',
                          '--out', str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    assert not any(ns.startswith('nmt-') for ns in os.listdir('/var/run/netns')), 'testbed left up'
    with open(tmp_path / 'profile.tsv') as f:
        rows = list(csv.DictReader(f, delimiter='\t'))
    base = float(next(r for r in rows if float(r['set_rtt_ms']) == 0 and float(r['set_rate_mbit']) == 0)['rtt_ms'])
    cell = next(r for r in rows if float(r['set_rtt_ms']) == 150 and float(r['set_rate_mbit']) == 50)
    assert abs(float(cell['rtt_ms']) - (150 + base)) <= 2.0, cell
    assert abs(float(cell['a_bw_mbit']) / 50 - 1) <= 0.10, cell
    assert abs(float(cell['passive_mbit']) / 50 - 1) <= 0.20, cell
