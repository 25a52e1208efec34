"""The sending side of a stream: go-back-N over a :class:`DiskQueue` with cumulative acknowledgements.

The sender keeps at most ``window`` records in flight (sent, not acknowledged) and sends them in batches of
at most ``batch_records`` records / ``batch_bytes`` payload bytes, never a record that is not yet synced.
An acknowledgement ``acked_seq`` (of this queue's epoch) acknowledges every record up to it. When no
acknowledgement makes progress for the current timeout, everything in flight is sent again from the oldest
unacknowledged record; each such timeout doubles the timeout (exponential backoff, at most ``max_backoff``)
so a dead link is probed rather than flooded. Any acknowledgement of this epoch, also one without progress
(the receiver repeats its ack while idle), shows the link is up and resets the timeout to ``ack_timeout``:
after an outage the records in flight are sent again at most ``ack_timeout`` after the first ack gets through.

The window starts after ``base``, the current receiver's cumulative ack. A receiver may acknowledge less than an
earlier one did (the stream's consumer moved: a store instance promoted with a state older than what the
instance before it acknowledged): the sender then goes back to that ack and sends everything after it again,
from the records the queue still holds (it keeps ``retain_records`` acknowledged ones, :class:`DiskQueue`);
each batch names ``floor`` (``DiskQueue.floor``), below which the queue holds nothing, so a receiver asking for
older records moves on instead of waiting for them. A lower ack from one receiver never happens otherwise (its
acks only grow and come over one connection), so going back costs at most a resent window when a stale ack of
the previous receiver arrives late; the receiver drops what it has as duplicates and acknowledges again.

Nothing here blocks or reads a clock: ``now`` (monotonic seconds) is an argument.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List

from cnr_store_forward.core.queue import DiskQueue, Record


@dataclass(frozen=True)
class SenderSettings:
    window: int                 # records in flight at most
    batch_records: int          # records per batch at most
    batch_bytes: int            # payload bytes per batch at most (a bigger single record goes alone)
    ack_timeout: float          # [s] without progress until the records in flight are sent again
    max_backoff: float          # [s] the timeout doubles with each timeout up to this


class Sender:
    """Go-back-N sender over ``queue`` (see the module docstring)."""

    def __init__(self, queue: DiskQueue, settings: SenderSettings) -> None:
        self.queue = queue
        self.settings = settings
        self.base = queue.acked               # the current receiver's cumulative ack
        self.next_seq = self.base + 1         # the next record to send
        self.highest_sent = queue.acked       # in this process: records above it were never sent
        self.timeout = settings.ack_timeout
        self.timer = 0.0                      # when the current timeout started
        self.sent = 0
        self.resent = 0
        self.timeouts = 0
        self.acks = 0
        self.stale_acks = 0
        self.skipped = 0
        self.rewinds = 0

    @property
    def in_flight(self) -> int:
        return max(0, self.next_seq - 1 - self.base)

    @property
    def pending(self) -> int:
        """Records the current receiver has not acknowledged."""
        return self.queue.last_seq - self.base

    def poll(self, now: float) -> List[Record]:
        """The next batch to send now (empty: nothing to send)."""
        q, s = self.queue, self.settings
        if self.in_flight and now - self.timer >= self.timeout:
            self.next_seq = self.base + 1         # go back: resend everything in flight
            self.timeouts += 1
            self.timeout = min(self.timeout * 2.0, s.max_backoff)
            self.timer = now
        last = min(q.synced_seq, self.base + s.window)
        if self.next_seq > last:
            return []
        if not self.in_flight:
            self.timer = now
        batch = q.records(self.next_seq, last, s.batch_records, s.batch_bytes)
        fresh = max(0, batch[-1].seq - self.highest_sent)
        self.sent += fresh
        self.resent += len(batch) - fresh
        self.highest_sent = max(self.highest_sent, batch[-1].seq)
        self.next_seq = batch[-1].seq + 1
        return batch

    def on_ack(self, epoch: int, acked_seq: int, now: float) -> int:
        """An acknowledgement arrived; returns the number of records it newly acknowledged.

        Acks of another epoch (an older queue) are ignored and counted in ``stale_acks``. An ack beyond the
        newest record (the receiver delivered records this queue lost, only possible without fsync) makes the
        queue continue after it (:meth:`DiskQueue.skip_to`), counted in ``skipped``. An ack below ``base`` (a
        receiver that holds less) goes back to it, or to the queue's ``floor`` if that is newer, and sends what
        follows again (counted in ``rewinds``).
        """
        q = self.queue
        if epoch != q.epoch:
            self.stale_acks += 1
            return 0
        self.acks += 1
        self.timeout = self.settings.ack_timeout      # the link is alive: no more backing off
        if acked_seq < self.base:
            self.base = max(acked_seq, q.floor)
            self.next_seq = self.base + 1
            self.rewinds += 1
            self.timer = now
            return 0
        if acked_seq == self.base:
            return 0
        if acked_seq > q.last_seq:
            newly = acked_seq - q.acked
            q.skip_to(acked_seq + 1)
            self.skipped += 1
        else:
            newly = q.ack(acked_seq) if acked_seq > q.acked else 0
        self.base = acked_seq
        self.next_seq = max(self.next_seq, acked_seq + 1)
        self.highest_sent = max(self.highest_sent, acked_seq)
        self.timer = now
        return newly
