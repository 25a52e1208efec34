"""The receiving side of a stream: in-order delivery, duplicates dropped by sequence number, a persisted mark.

The receiver follows one sender queue (its epoch) and remembers ``delivered``, the highest sequence number
it has delivered, in a small state file. A batch is accepted only from the next expected record on
(go-back-N: the sender resends after a gap); its records up to ``delivered`` are duplicates and dropped.
The caller delivers the accepted records, then calls :meth:`Receiver.commit`, which persists the mark,
then acknowledges ``delivered``. A crash between delivering and committing delivers those records again
after the restart (at most one batch per crash); nothing is lost.

Epochs: a batch of an unknown epoch comes from a new sender queue (its directory was created afresh). The
receiver switches to it, retires the old epoch (batches of a retired epoch are dropped as stale, so a late
batch of the old queue is never delivered again) and starts from the batch's ``acked_seq``: every record up
to the sender's cumulative ack has been delivered by some receiver before. For the same reason a receiver
whose state file is lost or older than the sender's ack moves its mark forward to that ack. (The sender's ack
in a batch is its queue's ``floor``: the records it no longer holds. It keeps acknowledged records for a while,
so a receiver whose mark is behind, e.g. a consumer promoted with an older copy of the mark, gets them again.)

The mark can travel: :meth:`Receiver.mark` is a JSON-able copy (epoch, delivered, retired epochs) and
:meth:`Receiver.adopt` takes one over (a store instance promoted with the state of the one before it holds the
mark that matches that state; it acknowledges from there and the sender sends what follows again).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Sequence, Tuple

from cnr_params.files import read_json, write_json

RETIRED_KEPT = 64           # retired epochs remembered (one per re-created sender queue)


@dataclass(frozen=True)
class Plan:
    """What to do with one batch: deliver ``records[start:]``, then commit and acknowledge (if ``ack``)."""
    start: int                  # index of the first record to deliver (len(records): none)
    ack: bool                   # acknowledge after delivering (False for a stale or malformed batch)


class Receiver:
    """Receiver state of one stream, persisted in ``state_path``.

    Args:
        state_path: the state file (JSON: epoch, delivered, retired epochs, message type); created when first
            needed.
        fsync: make each commit durable (fsync), else atomic only.
    """

    def __init__(self, state_path: str, fsync: bool) -> None:
        self.state_path = state_path
        self.fsync = fsync
        state = read_json(state_path) or {}
        self.epoch = state.get('epoch', 0) if isinstance(state.get('epoch'), int) else 0
        self.delivered = state.get('delivered', 0) if isinstance(state.get('delivered'), int) else 0
        retired = state.get('retired', [])
        self.retired: List[int] = [e for e in retired if isinstance(e, int)] if isinstance(retired, list) else []
        kind = state.get('kind', ['', ''])
        self.kind: Tuple[str, str] = (str(kind[0]), str(kind[1])) if isinstance(kind, list) and len(kind) == 2 \
            else ('', '')
        self.last_seq = self.delivered          # the newest seq received
        self.delivered_count = 0
        self.duplicates = 0
        self.out_of_order = 0
        self.stale = 0
        self.malformed = 0
        self.epoch_changes = 0
        self.fast_forwards = 0

    def plan(self, epoch: int, acked_seq: int, seqs: Sequence[int]) -> Plan:
        """Which records of a batch (``seqs``, consecutive) to deliver."""
        if epoch in self.retired or epoch == 0:
            self.stale += 1
            return Plan(len(seqs), ack=False)
        if any(b != a + 1 for a, b in zip(seqs, seqs[1:])):
            self.malformed += 1
            return Plan(len(seqs), ack=False)
        changed = False
        if epoch != self.epoch:
            if self.epoch:
                self.retired = (self.retired + [self.epoch])[-RETIRED_KEPT:]
            self.epoch = epoch
            self.delivered = self.last_seq = acked_seq
            self.epoch_changes += 1
            changed = True
        elif acked_seq > self.delivered:
            self.delivered = acked_seq
            self.fast_forwards += 1
            changed = True
        if changed:
            self._save()
        if not seqs:
            return Plan(0, ack=True)
        self.last_seq = max(self.last_seq, seqs[-1])
        expected = self.delivered + 1
        if seqs[0] > expected:
            self.out_of_order += len(seqs)
            return Plan(len(seqs), ack=True)
        start = min(expected - seqs[0], len(seqs))
        self.duplicates += start
        return Plan(start, ack=True)

    def mark(self) -> dict:
        """The delivered mark, JSON-able: ``{epoch, delivered, retired}``."""
        return {'epoch': self.epoch, 'delivered': self.delivered, 'retired': list(self.retired)}

    def adopt(self, mark: dict) -> None:
        """Take over a mark (:meth:`mark` of another receiver of this stream, checked by :func:`parse_mark`)
        and persist it."""
        m = parse_mark(mark)
        self.epoch, self.delivered, self.retired = m['epoch'], m['delivered'], m['retired']
        self.last_seq = self.delivered
        self._save()

    def commit(self, delivered_seq: int) -> None:
        """The records of the current epoch up to ``delivered_seq`` have been delivered: persist the mark."""
        if delivered_seq <= self.delivered:
            return
        self.delivered_count += delivered_seq - self.delivered
        self.delivered = delivered_seq
        self._save()

    def set_kind(self, kind: Tuple[str, str]) -> None:
        """Remember the stream's message type and MD5 sum (so a restarted receiver can advertise its output
        before the first batch arrives)."""
        if kind != self.kind:
            self.kind = kind
            self._save()

    def _save(self) -> None:
        write_json(self.state_path, {'epoch': self.epoch, 'delivered': self.delivered, 'retired': self.retired,
                                     'kind': list(self.kind)}, durable=self.fsync)


def parse_mark(mark: object, field: str = 'relay') -> dict:
    """A receiver's :meth:`Receiver.mark`, checked (ValueError naming ``field`` and the key)."""
    if not isinstance(mark, dict):
        raise ValueError(f'{field} must be an object, got {type(mark).__name__}')
    out = {}
    for key in ('epoch', 'delivered'):
        v = mark.get(key)
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise ValueError(f'{field}.{key} must be an integer >= 0, got {v!r}')
        out[key] = v
    retired = mark.get('retired')
    if not isinstance(retired, list) or not all(isinstance(e, int) and not isinstance(e, bool) for e in retired):
        raise ValueError(f'{field}.retired must be a list of integers, got {retired!r}')
    out['retired'] = list(retired)[-RETIRED_KEPT:]
    return out
