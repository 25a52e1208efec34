"""A_bw active probe with iperf3 (the thesis ran ``netperf -H <cloud>``, a 10 s TCP stream).

The client runs a time-bounded TCP stream whose first seconds are not measured::

    iperf3 -c ADDRESS -p PORT -J -t SECONDS -O OMIT -b CAP --connect-timeout MS

* ``-O OMIT``: TCP's slow start (and the loss recovery after its overshoot) is left out of the result: on a
  long fat link (150 ms, 50 Mbit/s) it takes about 1.5 s, and a short byte-bounded probe (``-n 1 MB``)
  measured a few Mbit/s there (benchmark in the package README).
* ``-t SECONDS``: the measured part; the bytes adapt to the link (rate x time), so a slow link costs
  little.
* ``-b CAP``: the sender is paced at ``CAP = max_bytes * 8 / (SECONDS + OMIT)`` bit/s, so a probe never
  sends more than about ``max_bytes`` however fast the link; CAP is also the largest A_bw it can report.
* killed after ``timeout`` seconds.

The result is the receiver's rate over the measured part (``end.sum_received.bits_per_second``); the bytes
are everything the sender sent, omitted seconds included (the sum of the client's intervals). Every
failure — no iperf3, refused or busy server, timeout, bad JSON, an ``"error"`` in the JSON — becomes a
:class:`ProbeResult` with ``ok=False`` and a message; nothing raises.
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
    bytes_sent: int             # bytes the sender sent, omitted seconds included (0 if unknown)
    seconds: float              # measured transfer time at the receiver [s] (NaN if unknown)
    error: str = ''


@dataclass
class ProbeSettings:
    seconds: int        # measured seconds (iperf3 -t, >= 1)
    omit: int           # leading seconds not measured (iperf3 -O, >= 0)
    max_bytes: int      # bytes per probe at most (the sender's pacing cap)
    timeout: float      # s until the client is killed (> seconds + omit)

    @property
    def cap(self) -> int:
        """The sender's pacing rate [bit/s]: ``max_bytes`` over the whole probe; the largest A_bw it measures."""
        return max(1, int(self.max_bytes * 8 / (self.seconds + self.omit)))


def iperf3_command(executable: str, address: str, port: int, settings: ProbeSettings) -> List[str]:
    """The iperf3 client command line of one bounded probe."""
    connect_ms = max(1, int(settings.timeout * 1000 / 2))
    return [executable, '-c', address, '-p', str(port), '-J', '-t', str(settings.seconds),
            '-O', str(settings.omit), '-b', str(settings.cap), '--connect-timeout', str(connect_ms)]


def _sent_bytes(data: dict, summary: dict) -> int:
    """Bytes the sender sent: the sum of its intervals (omitted ones included), at least ``sum_sent.bytes``."""
    total = 0
    intervals = data.get('intervals') if isinstance(data.get('intervals'), list) else []
    for interval in intervals:
        part = interval.get('sum') if isinstance(interval, dict) else None
        value = part.get('bytes') if isinstance(part, dict) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0:
            total += int(value)
    value = summary.get('bytes', 0)
    return max(total, int(value) if isinstance(value, (int, float)) and value >= 0 else 0)


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
    nbytes = _sent_bytes(data, sent)
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


def run_probe(address: str, port: int, settings: ProbeSettings, executable: str,
              runner: Optional[Runner] = None) -> ProbeResult:
    """Run one bounded iperf3 probe; never raises.

    Args:
        address: the peer's address, where an ``iperf3 -s`` listens.
        port: its port.
        settings: duration, omitted seconds, byte cap and timeout.
        executable: the iperf3 program.
        runner: ``(argv, timeout) -> CompletedProcess`` (tests inject a fake; default subprocess.run).
    """
    argv = iperf3_command(executable, address, port, settings)
    try:
        done = (runner or _run)(argv, settings.timeout)
    except subprocess.TimeoutExpired:
        return ProbeResult(False, math.nan, 0, math.nan, f'iperf3: no result within {settings.timeout:g} s')
    except OSError as exc:
        return ProbeResult(False, math.nan, 0, math.nan, f'cannot run {executable}: {exc.strerror or exc}')
    result = parse_iperf3_json(done.stdout or '')
    if not result.ok and not (done.stdout or '').strip():
        err = (done.stderr or '').strip().splitlines()
        result.error = f'iperf3 exited with {done.returncode}' + (f': {err[-1]}' if err else '')
    return result
