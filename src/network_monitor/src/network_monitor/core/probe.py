"""A_bw active probe with iperf3 (the thesis ran ``netperf -H <cloud>``).

The client runs ``iperf3 -c ADDRESS -p PORT -J -n BYTES --connect-timeout MS`` and is killed after
``timeout`` seconds, so a probe costs at most ``BYTES`` and ``timeout``. The result is the receiver's
rate (``end.sum_received.bits_per_second``). Every failure — no iperf3, refused or busy server, timeout,
bad JSON, an ``"error"`` in the JSON — becomes a :class:`ProbeResult` with ``ok=False`` and a message;
nothing raises.
"""
from __future__ import annotations

import json
import math
import subprocess
from dataclasses import dataclass
from typing import Callable, List, Optional


@dataclass
class ProbeResult:
    ok: bool
    bits_per_second: float      # receiver's rate [bit/s] (NaN on failure)
    bytes_sent: int             # bytes the probe put on the link (0 if unknown)
    seconds: float              # transfer time [s] (NaN if unknown)
    error: str = ''


def iperf3_command(executable: str, address: str, port: int, nbytes: int, timeout: float) -> List[str]:
    """The iperf3 client command line of one bounded probe."""
    connect_ms = max(1, int(timeout * 1000 / 2))
    return [executable, '-c', address, '-p', str(port), '-J', '-n', str(nbytes),
            '--connect-timeout', str(connect_ms)]


def parse_iperf3_json(text: str) -> ProbeResult:
    """The result of an ``iperf3 -J`` client run from its output."""
    try:
        data = json.loads(text)
    except ValueError:
        first = text.strip().splitlines()[0][:200] if text.strip() else 'no output'
        return ProbeResult(False, math.nan, 0, math.nan, f'iperf3 output is not JSON: {first}')
    if not isinstance(data, dict):
        return ProbeResult(False, math.nan, 0, math.nan, 'iperf3 output is not a JSON object')
    end = data.get('end') if isinstance(data.get('end'), dict) else {}
    sent = end.get('sum_sent') if isinstance(end.get('sum_sent'), dict) else {}
    received = end.get('sum_received') if isinstance(end.get('sum_received'), dict) else {}
    nbytes = sent.get('bytes', 0)
    nbytes = int(nbytes) if isinstance(nbytes, (int, float)) and nbytes >= 0 else 0
    if data.get('error'):
        return ProbeResult(False, math.nan, nbytes, math.nan, f'iperf3: {data["error"]}')
    bps = received.get('bits_per_second')
    seconds = received.get('seconds', math.nan)
    if not isinstance(bps, (int, float)) or isinstance(bps, bool) or not math.isfinite(bps) or bps <= 0:
        return ProbeResult(False, math.nan, nbytes, math.nan, 'iperf3: no received rate in the result')
    return ProbeResult(True, float(bps), nbytes, float(seconds) if isinstance(seconds, (int, float)) else math.nan)


Runner = Callable[[List[str], float], 'subprocess.CompletedProcess[str]']


def _run(argv: List[str], timeout: float) -> 'subprocess.CompletedProcess[str]':
    return subprocess.run(argv, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def run_probe(address: str, port: int, nbytes: int, timeout: float, executable: str = 'iperf3',
              runner: Optional[Runner] = None) -> ProbeResult:
    """Run one bounded iperf3 probe; never raises.

    Args:
        address: the peer's address, where an ``iperf3 -s`` listens.
        port: its port.
        nbytes: bytes to send (``-n``).
        timeout: seconds until the client is killed.
        executable: the iperf3 program.
        runner: ``(argv, timeout) -> CompletedProcess`` (tests inject a fake; default subprocess.run).
    """
    argv = iperf3_command(executable, address, port, nbytes, timeout)
    try:
        done = (runner or _run)(argv, timeout)
    except subprocess.TimeoutExpired:
        return ProbeResult(False, math.nan, 0, math.nan, f'iperf3: no result within {timeout:g} s')
    except OSError as exc:
        return ProbeResult(False, math.nan, 0, math.nan, f'cannot run {executable}: {exc.strerror or exc}')
    result = parse_iperf3_json(done.stdout or '')
    if not result.ok and not (done.stdout or '').strip():
        err = (done.stderr or '').strip().splitlines()
        result.error = f'iperf3 exited with {done.returncode}' + (f': {err[-1]}' if err else '')
    return result
