"""The store as the receiving end of the store-and-forward relay (ROS-free; README "Input through the relay").

With ``~relay_stream`` set, local_mapcell_manager takes its merged measurements from the relay's batches
(cnr_store_forward: a disk queue on the robot, go-back-N, cumulative acks) instead of the merger's topic, and
acknowledges them itself, after its own durable write: :func:`take_batch` stores the new records of a batch
through the :class:`Ledger` (its duplicate rule, each row fsync'ed), then persists the relay's delivered mark (a
:class:`cnr_store_forward.core.receiver.Receiver` whose state file lies next to the store, :func:`mark_path`),
and only then may the node acknowledge (a batch's new rows: one write, one fsync). The mark is part of the instance's state (key ``relay``, :func:`state_mark`),
so a promoted instance acknowledges from the mark that matches the store it took over, and the sender sends
everything after it again: what the instance before it acknowledged but did not hand over (a failover from a
replica older than its last ack) comes again, what it handed over comes again only as duplicates.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple

from cnr_maps.measurements import Measurement
from cnr_store_forward.core.receiver import Receiver, parse_mark
from local_mapcell_manager.core.ledger import DUPLICATE, OUTSIDE, Ledger, Reading

STATE_KEY = 'relay'


def mark_path(store_path: str) -> str:
    """The relay's delivered mark of the store ``store_path`` (JSON next to it)."""
    return store_path + '.relay.json'


def state_mark(state: Any) -> Dict[str, Any]:
    """The relay mark a handed-over state holds, checked.

    Raises:
        ValueError: missing or malformed, naming the field.
    """
    if not isinstance(state, dict) or STATE_KEY not in state:
        raise ValueError(f'local_mapcell_manager state: {STATE_KEY} is missing (a state of an instance that '
                         f'takes its input through the relay)')
    try:
        return parse_mark(state[STATE_KEY], STATE_KEY)
    except ValueError as exc:
        raise ValueError(f'local_mapcell_manager state: {exc}') from None


class Taken:
    """What :func:`take_batch` did with one batch."""

    def __init__(self) -> None:
        self.ack = False                          # acknowledge the receiver's mark now
        self.stored: List[Measurement] = []       # new measurements, in order
        self.duplicates = 0                       # records the duplicate rule dropped (already stored)
        self.outside = 0                          # records outside the grid
        self.undecodable = 0                      # records that are not a readable measurement (skipped)
        self.skipped = 0                          # records the mark moved past without receiving them


def take_batch(receiver: Receiver, ledger: Ledger, epoch: int, floor: int,
               records: Sequence[Tuple[int, Optional[Reading]]]) -> Taken:
    """Store one batch of the relay (``records``: ``(seq, reading)``, reading None when it could not be read)
    and persist the mark; the ledger must be storing (the active instance). ``floor``: the batch's
    ``acked_seq``, the newest record the sender no longer holds.

    Raises:
        OSError: the store or the mark cannot be written (nothing acknowledged; the records come again).
    """
    out = Taken()
    before = receiver.delivered if receiver.epoch == epoch else None
    plan = receiver.plan(epoch, floor, [seq for seq, _ in records])
    if before is not None and receiver.delivered > before:
        out.skipped = receiver.delivered - before
    new = records[plan.start:]
    readings = [r for _, r in new if r is not None]
    out.undecodable = len(new) - len(readings)
    for outcome, m in ledger.receive_many(readings):        # one write and one fsync for the batch
        if m is not None:
            out.stored.append(m)
        elif outcome == DUPLICATE:
            out.duplicates += 1
        elif outcome == OUTSIDE:
            out.outside += 1
    if new:
        receiver.commit(new[-1][0])
    out.ack = plan.ack
    return out
