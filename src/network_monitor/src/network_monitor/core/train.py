"""A_bw from the dispersion of a short UDP packet train (WBest-like; a cheap alternative to the iperf3 probe).

The sender puts ``count`` packets of ``packet_bytes`` (UDP payload) back-to-back on the link; the peer's
responder timestamps their arrivals and answers with one summary datagram. The link's bottleneck spaces the
packets by its serialisation time, so the arrivals' dispersion gives the rate the link serves the train at:

    A = W * 8 * (s_last - s_first) / (t_last - t_first)

over the packets that came back after the first one (their first and last sequence numbers ``s`` and arrival
times ``t``), ``W`` =
``packet_bytes`` + 28 (the IPv4 and UDP headers: the link carries, and C_bw counts, whole IP packets). That is
``W * 8`` over the train's mean dispersion per packet (WBest). The first arrival is left out: a packet that
waited alone (the sender's first ``send`` resolving the route, a transmitter waking up) stretches or squeezes
only its own gap. A packet lost in between still took its turn on the link (the emulator and a radio lose
packets after sending them), so the span counts it: random loss does not bias A, and is reported on its own
(:attr:`TrainEstimate.loss`). The capacity C is ``W * 8`` over the median gap between back-to-back pairs
(consecutive sequence numbers that both arrived) — WBest's packet-pair estimate; with no cross traffic C and
A agree. Fewer than :func:`minimum_received` packets back, or no dispersion at all, is a failed probe.

Wire format (network byte order):

* train packet: ``TRAIN_HEADER`` = magic ``CNRT``, train id (u32), seq (u32), count (u32), the sender's
  wall-clock send time (i64 ns), zero-padded to ``packet_bytes``;
* summary: ``SUMMARY_HEADER`` = magic ``CNRS``, train id (u32), count (u32), entries (u32), then per arrived
  packet ``SUMMARY_ENTRY`` = seq (u32), arrival offset from the first arrival (i64 ns), in arrival order.

A summary of at most :data:`MAX_PACKETS` entries fits one unfragmented 1500-byte-MTU datagram. Parsing never
raises: anything malformed is ``None``.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

from network_monitor.core.echo import quantile
from network_monitor.core.probe import ProbeResult

TRAIN_MAGIC = b'CNRT'
SUMMARY_MAGIC = b'CNRS'
TRAIN_HEADER = struct.Struct('!4sIIIq')      # magic, train id, seq, count, send time [ns]
SUMMARY_HEADER = struct.Struct('!4sIII')     # magic, train id, count, entries
SUMMARY_ENTRY = struct.Struct('!Iq')         # seq, arrival offset [ns]
IP_UDP_OVERHEAD = 28                         # bytes: IPv4 (20) + UDP (8) headers around each payload
MAX_DATAGRAM = 1472                          # UDP payload of a 1500-byte MTU
MAX_PAYLOAD = 65507                          # the largest UDP payload over IPv4
MAX_PACKETS = (MAX_DATAGRAM - SUMMARY_HEADER.size) // SUMMARY_ENTRY.size   # 121

Arrival = Tuple[int, int]                    # (seq, arrival time [ns], any origin)


@dataclass
class TrainSettings:
    packets: int         # packets per train (3 .. MAX_PACKETS)
    packet_bytes: int    # UDP payload per packet (TRAIN_HEADER.size .. MAX_PAYLOAD)
    gap: float           # s the responder waits after the last arrival of an incomplete train before answering
    timeout: float       # s the sender waits for the summary, sending included

    @property
    def train_bytes(self) -> int:
        """UDP payload bytes one train puts on the link (60 x 1472 = 88320)."""
        return self.packets * self.packet_bytes


@dataclass
class TrainPacket:
    train_id: int
    seq: int
    count: int
    sent_ns: int


@dataclass
class Summary:
    train_id: int
    count: int
    arrivals: List[Arrival]      # (seq, offset [ns] from the first arrival), in arrival order


def train_packet(train_id: int, seq: int, count: int, sent_ns: int, packet_bytes: int) -> bytes:
    """One train packet, zero-padded to ``packet_bytes`` (at least the header)."""
    header = TRAIN_HEADER.pack(TRAIN_MAGIC, train_id, seq, count, sent_ns)
    return header + bytes(max(0, packet_bytes - len(header)))


def parse_train_packet(data: bytes) -> Optional[TrainPacket]:
    """The header of a train packet; None if ``data`` is not one."""
    if len(data) < TRAIN_HEADER.size:
        return None
    magic, train_id, seq, count, sent_ns = TRAIN_HEADER.unpack_from(data)
    if magic != TRAIN_MAGIC or count == 0 or seq >= count:
        return None
    return TrainPacket(train_id, seq, count, sent_ns)


def summary_datagram(train_id: int, count: int, arrivals: Sequence[Arrival]) -> bytes:
    """The responder's answer: the arrivals (seq, time [ns]) as offsets from the first, in arrival order, at
    most :data:`MAX_PACKETS` of them (the earliest)."""
    ordered = sorted(arrivals, key=lambda a: a[1])[:MAX_PACKETS]
    first = ordered[0][1] if ordered else 0
    body = b''.join(SUMMARY_ENTRY.pack(seq, t - first) for seq, t in ordered)
    return SUMMARY_HEADER.pack(SUMMARY_MAGIC, train_id, count, len(ordered)) + body


def parse_summary(data: bytes) -> Optional[Summary]:
    """A summary datagram; None if ``data`` is not one (wrong magic, truncated)."""
    if len(data) < SUMMARY_HEADER.size:
        return None
    magic, train_id, count, entries = SUMMARY_HEADER.unpack_from(data)
    if magic != SUMMARY_MAGIC or len(data) != SUMMARY_HEADER.size + entries * SUMMARY_ENTRY.size:
        return None
    arrivals = [SUMMARY_ENTRY.unpack_from(data, SUMMARY_HEADER.size + i * SUMMARY_ENTRY.size)
                for i in range(entries)]
    return Summary(train_id, count, arrivals)


def minimum_received(count: int) -> int:
    """Packets that must come back for an estimate: half the train, at least 3 (two gaps after the first)."""
    return max(3, (count + 1) // 2)


@dataclass
class TrainEstimate:
    ok: bool
    bits_per_second: float   # A: the dispersion rate of the train (NaN on failure)
    capacity: float          # C: from the median back-to-back gap [bit/s] (NaN if no pair)
    received: int            # distinct packets that came back
    count: int               # packets sent
    seconds: float           # t_last - t_first over the packets used [s] (NaN if unknown)
    error: str = ''

    @property
    def loss(self) -> float:
        """Fraction of the train that did not come back."""
        return 1.0 - self.received / self.count if self.count else math.nan

    def result(self, bytes_sent: int) -> ProbeResult:
        """As a probe result (the node treats the iperf3 and the train probe alike)."""
        return ProbeResult(self.ok, self.bits_per_second, bytes_sent, self.seconds, self.error)


def estimate_train(arrivals: Sequence[Arrival], count: int, packet_bytes: int) -> TrainEstimate:
    """A and C from a train's arrivals (seq, time [ns]); seqs outside ``0..count-1`` and repeats are ignored."""
    seen = {}
    for seq, t in arrivals:
        if 0 <= seq < count and seq not in seen:
            seen[seq] = t
    ordered = sorted(seen.items(), key=lambda a: (a[1], a[0]))
    received = len(ordered)
    need = minimum_received(count)
    if received < need:
        return TrainEstimate(False, math.nan, math.nan, received, count, math.nan,
                             f'train: only {received} of {count} packets came back (at least {need} needed)')
    wire_bits = (packet_bytes + IP_UDP_OVERHEAD) * 8
    used = ordered[1:]
    span_ns = used[-1][1] - used[0][1]
    gaps = [b[1] - a[1] for a, b in zip(ordered, ordered[1:]) if b[0] == a[0] + 1]
    gap = quantile(sorted(gaps), 0.5)
    capacity = wire_bits * 1e9 / gap if gap > 0 else math.nan
    if span_ns <= 0:
        return TrainEstimate(False, math.nan, capacity, received, count, 0.0,
                             f'train: {received} of {count} packets arrived with no dispersion')
    seconds = span_ns / 1e9
    seqs = [seq for seq, _ in used]
    return TrainEstimate(True, wire_bits * (max(seqs) - min(seqs)) / seconds, capacity, received, count, seconds)
