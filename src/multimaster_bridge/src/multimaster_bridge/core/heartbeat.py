"""Link quality from heartbeats: RTT, loss and clock offset, NTP-style (ROS-free).

A heartbeat carries its send time t1 and echoes the peer's latest heartbeat (its t1 as ``t1``, our receive
time as ``t2``, and our send time t3). On receipt at t4: rtt = (t4 - t1) - (t3 - t2),
offset = ((t2 - t1) + (t3 - t4)) / 2 (peer clock - local clock).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Deque, Optional


@dataclass
class Quality:
    alive: bool
    rtt: float
    rtt_stddev: float
    loss: float
    clock_offset: float
    sent: int
    received: int


class LinkEstimator:
    """Per-peer estimator.

    Args:
        rate: heartbeat rate [Hz] (to count expected heartbeats).
        loss_timeout: the peer is lost when nothing was heard for this long [s].
        window: seconds of history for loss and RTT statistics.
    """

    def __init__(self, rate: float, loss_timeout: float, window: float = 5.0) -> None:
        self.rate = rate
        self.loss_timeout = loss_timeout
        self.window = window
        self.last_heard = -math.inf
        self.received_times: Deque[float] = deque()
        self.rtts: Deque[float] = deque(maxlen=50)
        self.offset = math.nan
        self.sent = 0
        self.received = 0
        self.peer_first_heard = math.inf

    def on_sent(self) -> None:
        self.sent += 1

    def on_heartbeat(self, now: float, t1: Optional[float] = None, t2: Optional[float] = None,
                     t3: Optional[float] = None, t4: Optional[float] = None) -> None:
        """A heartbeat arrived at ``now`` (monotonic); (t1, t2, t3) from its echo when it has one.

        ``t4`` is the arrival time on the clock of t1 (wall clock, so that the offset means something);
        it defaults to ``now``.
        """
        t4 = now if t4 is None else t4
        self.received += 1
        self.last_heard = now
        self.peer_first_heard = min(self.peer_first_heard, now)
        self.received_times.append(now)
        while self.received_times and self.received_times[0] < now - self.window:
            self.received_times.popleft()
        if t1 is not None and t2 is not None and t3 is not None:
            rtt = (t4 - t1) - (t3 - t2)
            if rtt >= 0:
                self.rtts.append(rtt)
                self.offset = ((t2 - t1) + (t3 - t4)) / 2.0

    def alive(self, now: float) -> bool:
        return now - self.last_heard <= self.loss_timeout

    def quality(self, now: float) -> Quality:
        while self.received_times and self.received_times[0] < now - self.window:
            self.received_times.popleft()
        span = min(self.window, max(now - self.peer_first_heard, 1e-9))
        expected = max(1.0, span * self.rate)
        loss = max(0.0, 1.0 - len(self.received_times) / expected) if math.isfinite(span) else 1.0
        rtts = list(self.rtts)[-20:]
        rtt = sum(rtts) / len(rtts) if rtts else math.nan
        std = math.sqrt(sum((r - rtt) ** 2 for r in rtts) / len(rtts)) if len(rtts) > 1 else math.nan
        return Quality(self.alive(now), rtt, std, min(loss, 1.0), self.offset, self.sent, self.received)
