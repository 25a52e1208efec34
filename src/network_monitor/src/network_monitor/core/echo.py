"""RTT and loss from a topic echo (thesis §4.2.4, Fig. 4-18).

The monitor sends pings (sequence number + send time) that the peer's monitor publishes back unchanged.
:class:`EchoStats` keeps the send time of every ping inside the window, matches the replies by sequence
number and reports the median RTT, its spread (interquartile range) and the loss ratio. A ping is *decided*
once answered or once ``reply_timeout`` has passed unanswered; loss = unanswered / decided. A reply that
arrives after its timeout, twice, or for an unknown sequence number is ignored (the ping stays lost).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence


def quantile(sorted_values: Sequence[float], q: float) -> float:
    """Linear-interpolation quantile of already sorted values (NaN for none)."""
    if not sorted_values:
        return math.nan
    pos = (len(sorted_values) - 1) * q
    lo = int(math.floor(pos))
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)


@dataclass
class EchoSummary:
    """RTT statistics at one instant. Times in seconds; NaN where there is no data."""
    rtt: float
    rtt_spread: float
    loss: float
    sent: int          # pings sent within the window
    answered: int      # of which answered in time
    decided: int       # answered or timed out
    last_reply: float  # local time of the newest in-time reply (-inf if none)

    @property
    def has_data(self) -> bool:
        return self.decided > 0


class EchoStats:
    """Ping bookkeeping over a sliding window.

    Args:
        window: seconds of pings the statistics cover (> 0).
        reply_timeout: seconds after which an unanswered ping counts as lost (> 0).
    """

    def __init__(self, window: float, reply_timeout: float) -> None:
        if not window > 0 or not reply_timeout > 0:
            raise ValueError('window and reply_timeout must be > 0')
        self.window = window
        self.reply_timeout = reply_timeout
        self.next_seq = 1
        self._sent: Dict[int, float] = {}          # seq -> local send time
        self._rtt: Dict[int, float] = {}           # seq -> rtt of in-time replies
        self.last_reply = -math.inf

    def send(self, now: float) -> int:
        """Record a ping sent at ``now``; returns its sequence number."""
        seq = self.next_seq
        self.next_seq += 1
        self._sent[seq] = now
        self._prune(now)
        return seq

    def reply(self, seq: int, now: float) -> Optional[float]:
        """A reply for ``seq`` received at ``now``; returns its RTT, or None if it was ignored."""
        sent = self._sent.get(seq)
        if sent is None or seq in self._rtt:
            return None
        rtt = now - sent
        if rtt < 0 or rtt > self.reply_timeout:
            return None
        self._rtt[seq] = rtt
        self.last_reply = max(self.last_reply, now)
        return rtt

    def _prune(self, now: float) -> None:
        horizon = now - self.window
        for seq in [s for s, t in self._sent.items() if t < horizon]:
            del self._sent[seq]
            self._rtt.pop(seq, None)

    def summary(self, now: float) -> EchoSummary:
        """Statistics of the pings sent in ``[now - window, now]``."""
        self._prune(now)
        rtts = sorted(self._rtt.values())
        answered = len(rtts)
        timed_out = sum(1 for s, t in self._sent.items() if s not in self._rtt and now - t > self.reply_timeout)
        decided = answered + timed_out
        return EchoSummary(
            rtt=quantile(rtts, 0.5),
            rtt_spread=(quantile(rtts, 0.75) - quantile(rtts, 0.25)) if rtts else math.nan,
            loss=(timed_out / decided) if decided else math.nan,
            sent=len(self._sent), answered=answered, decided=decided, last_reply=self.last_reply)


def is_alive(last_reply: float, now: float, alive_timeout: float) -> bool:
    """The peer answered within ``alive_timeout`` seconds of ``now``."""
    return now - last_reply <= alive_timeout


@dataclass
class LinkSample:
    """The bridge's view of the link (cnr_msgs/LinkQuality), with the local time it arrived."""
    received: float
    alive: bool
    rtt: float
    rtt_stddev: float
    loss: float


@dataclass
class LinkState:
    alive: bool
    rtt: float
    rtt_spread: float
    loss: float
    source: str        # 'echo' | 'link_quality' | 'none'


def link_state(summary: EchoSummary, now: float, alive_timeout: float, bridge: Optional[LinkSample],
               bridge_timeout: float) -> LinkState:
    """alive/RTT/loss from our own echo; when it has no decided ping yet (start, or pings not answered
    nor timed out), from a bridge sample younger than ``bridge_timeout`` (its spread is the bridge's RTT
    standard deviation); else not alive and unknown."""
    if summary.has_data:
        return LinkState(is_alive(summary.last_reply, now, alive_timeout), summary.rtt, summary.rtt_spread,
                         summary.loss, 'echo')
    if bridge is not None and 0 <= now - bridge.received <= bridge_timeout:
        return LinkState(bridge.alive, bridge.rtt, bridge.rtt_stddev, bridge.loss, 'link_quality')
    return LinkState(False, math.nan, math.nan, math.nan, 'none')
