"""The packet-train probe over UDP (ROS-free): the sender (:func:`run_train_probe`, robot -> peer) and the
peer's responder (:class:`TrainResponder`). Wire format and estimator: :mod:`network_monitor.core.train`.

The responder stamps each arrival with the kernel's receive time (``SO_TIMESTAMPNS``; the clock read after
``recvmsg`` where the kernel gives none), so a busy Python thread does not squeeze the dispersion. It answers a
train with one summary datagram (sent twice, against a lost reply) once every packet arrived, or ``gap``
seconds after its last arrival. The sender waits for it at most ``timeout`` seconds; every failure is a
:class:`ProbeResult` with ``ok=False`` and a message, nothing raises.
"""
from __future__ import annotations

import math
import os
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple

from network_monitor.core.probe import ProbeResult
from network_monitor.core.train import (TrainSettings, estimate_train, parse_summary, parse_train_packet,
                                        summary_datagram, train_packet)

SUMMARY_COPIES = 2                  # the summary is sent this often (a lost reply would fail the probe)
BUFFER_BYTES = 1 << 20              # receive buffer asked for (the kernel caps it at net.core.rmem_max)
_TIMESPEC = struct.Struct('@qq')    # struct timespec of SCM_TIMESTAMPNS (64-bit Linux)
# SO_TIMESTAMPNS (= SCM_TIMESTAMPNS) of asm-generic/socket.h (x86, arm): Python's socket module does not export it
_SO_TIMESTAMPNS = getattr(socket, 'SO_TIMESTAMPNS', 35 if sys.platform.startswith('linux') else None)


def run_train_probe(address: str, port: int, settings: TrainSettings) -> ProbeResult:
    """Send one train to the responder at ``address:port`` and estimate A_bw from its summary; never raises."""
    deadline = time.monotonic() + settings.timeout
    where = f'{address}:{port}'
    sent = 0

    def failed(message: str) -> ProbeResult:
        return ProbeResult(False, math.nan, sent * settings.packet_bytes, math.nan, f'train to {where}: {message}')

    try:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    except OSError as exc:
        return failed(f'no socket: {exc.strerror or exc}')
    with sock:
        try:
            sock.settimeout(settings.timeout)
            sock.connect((address, port))      # connected: a port nobody listens on is reported (ICMP)
            train_id = int.from_bytes(os.urandom(4), 'big')
            for seq in range(settings.packets):
                sock.send(train_packet(train_id, seq, settings.packets, time.time_ns(), settings.packet_bytes))
                sent += 1
        except ConnectionRefusedError:
            return failed('nothing listens there (port unreachable)')
        except socket.timeout:
            return failed(f'sending blocked for {settings.timeout:g} s')
        except OSError as exc:
            return failed(exc.strerror or str(exc))
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return failed(f'no reply within {settings.timeout:g} s')
            try:
                sock.settimeout(remaining)
                data = sock.recv(65535)
            except socket.timeout:
                return failed(f'no reply within {settings.timeout:g} s')
            except ConnectionRefusedError:
                return failed('nothing listens there (port unreachable)')
            except OSError as exc:
                return failed(exc.strerror or str(exc))
            summary = parse_summary(data)
            if summary is not None and summary.train_id == train_id:
                break
    result = estimate_train(summary.arrivals, settings.packets, settings.packet_bytes).result(
        sent * settings.packet_bytes)
    if not result.ok:
        result.error = f'{result.error} ({where})'
    return result


@dataclass
class _Train:
    count: int
    last: float                                              # local monotonic time of the newest arrival
    arrivals: Dict[int, int] = field(default_factory=dict)   # seq -> arrival time [ns]


class TrainResponder:
    """Answers packet trains on a UDP port, in its own thread.

    Args:
        port: UDP port to listen on (0: any free one, see :attr:`port`).
        gap: seconds after the last arrival of an incomplete train until it is answered.
        bind: local address ('' = every interface).
        max_trains: trains tracked at once (one per sender normally); the oldest is dropped beyond.
        on_error: called with a one-line message when receiving fails (the node logs it).
    """

    def __init__(self, port: int, gap: float, bind: str = '', max_trains: int = 16,
                 on_error: Optional[Callable[[str], None]] = None) -> None:
        self.gap = gap
        self.on_error = on_error
        self.max_trains = max_trains
        self.kernel_stamps = False
        self.answered = 0                                       # trains answered
        self._trains: Dict[Tuple[Tuple[str, int], int], _Train] = {}
        self._done: List[Tuple[Tuple[str, int], int]] = []     # recently answered (late packets are ignored)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, BUFFER_BYTES)
            if _SO_TIMESTAMPNS is not None:
                try:
                    self.sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                    self.kernel_stamps = True
                except OSError:
                    pass
            self.sock.bind((bind, port))
        except OSError:
            self.sock.close()
            raise
        self.port = self.sock.getsockname()[1]

    @classmethod
    def start(cls, port: int, gap: float, bind: str = '',
              on_error: Optional[Callable[[str], None]] = None) -> 'TrainResponder':
        """A responder serving in a daemon thread; raises OSError if the port cannot be bound."""
        responder = cls(port, gap, bind, on_error=on_error)
        responder._thread = threading.Thread(target=responder.serve, name='train_responder', daemon=True)
        responder._thread.start()
        return responder

    def close(self) -> None:
        """Stop serving (within one poll period) and release the port."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self.sock.close()

    # ------------------------------------------------------------------------------------------------------
    def serve(self) -> None:
        """Receive and answer until :meth:`close`."""
        ancillary = socket.CMSG_SPACE(_TIMESPEC.size) if self.kernel_stamps else 0
        while not self._stop.is_set():
            now = time.monotonic()
            due = min((t.last + self.gap for t in self._trains.values()), default=now + 0.2)
            try:
                self.sock.settimeout(min(0.2, max(0.001, due - now)))
                data, cmsgs, _flags, sender = self.sock.recvmsg(65535, ancillary)
            except socket.timeout:
                data = None
            except OSError as exc:
                if self._stop.is_set():
                    return
                if self.on_error is not None:
                    self.on_error(f'train responder: {exc.strerror or exc}')
                self._stop.wait(0.1)         # a persistent error must not spin
                data = None
            if data is not None:
                self._arrived(data, cmsgs, sender)
            self._expire(time.monotonic())

    def _arrived(self, data: bytes, cmsgs: list, sender: Tuple[str, int]) -> None:
        stamp = next((_TIMESPEC.unpack(d[:_TIMESPEC.size]) for level, kind, d in cmsgs
                      if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(d) >= _TIMESPEC.size),
                     None)
        arrived_ns = stamp[0] * 1_000_000_000 + stamp[1] if stamp else time.time_ns()
        packet = parse_train_packet(data)
        if packet is None:
            return
        key = (sender, packet.train_id)
        if key in self._done:
            return
        train = self._trains.get(key)
        if train is None:
            if len(self._trains) >= self.max_trains:
                del self._trains[min(self._trains, key=lambda k: self._trains[k].last)]
            train = self._trains[key] = _Train(packet.count, time.monotonic())
        train.last = time.monotonic()
        train.arrivals.setdefault(packet.seq, arrived_ns)
        if len(train.arrivals) >= train.count:
            self._answer(key)

    def _expire(self, now: float) -> None:
        for key in [k for k, t in self._trains.items() if now - t.last >= self.gap]:
            self._answer(key)

    def _answer(self, key: Tuple[Tuple[str, int], int]) -> None:
        train = self._trains.pop(key)
        self._done = (self._done + [key])[-self.max_trains:]
        reply = summary_datagram(key[1], train.count, list(train.arrivals.items()))
        self.answered += 1
        for _ in range(SUMMARY_COPIES):
            try:
                self.sock.sendto(reply, key[0])
            except OSError:
                return
