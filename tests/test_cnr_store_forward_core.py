"""cnr_store_forward core without ROS: the disk queue (order, torn tails, restarts, bounds, compaction), the
go-back-N sender and the deduplicating receiver over a lossy, duplicating, reordering channel."""
from __future__ import annotations

import os
import random
from typing import List, Tuple

import pytest

from cnr_params import ConfigError, Section
from cnr_store_forward.core import config as sf_config
from cnr_store_forward.core.queue import (RECORD_HEADER, SEGMENT_HEADER, DiskQueue, QueueCorrupt, QueueLocked,
                                          frame)
from cnr_store_forward.core.receiver import Receiver, parse_mark
from cnr_store_forward.core.sender import Sender, SenderSettings

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def open_queue(path, max_records=1000, max_bytes=1 << 20, segment_bytes=1 << 16, fsync=False) -> DiskQueue:
    return DiskQueue(str(path), max_records, max_bytes, segment_bytes, fsync)


def payload(i: int) -> bytes:
    return f'message {i} '.encode() * (1 + i % 7)


def segments(path) -> List[str]:
    return sorted(os.path.join(str(path), n) for n in os.listdir(str(path)) if n.endswith('.seg'))


# ---------------------------------------------------------------- queue
def test_records_come_back_in_order_with_consecutive_seqs(tmp_path):
    q = open_queue(tmp_path)
    assert q.recovery.created and q.last_seq == 0 and q.acked == 0
    seqs = [q.append(payload(i), 1000 + i) for i in range(1, 51)]
    assert seqs == list(range(1, 51))
    got = q.records(1, 50, max_count=100, max_bytes=1 << 20)
    assert [r.seq for r in got] == seqs and [r.data for r in got] == [payload(i) for i in range(1, 51)]
    assert [r.stamp_ns for r in got] == [1000 + i for i in range(1, 51)]
    assert q.unacked == 50 and q.unacked_bytes == sum(len(frame(i, 0, payload(i))) for i in range(1, 51))
    q.close()


def test_batches_respect_count_and_bytes_but_never_come_back_empty(tmp_path):
    q = open_queue(tmp_path)
    for _ in range(10):
        q.append(b'x' * 100, 0)
    assert len(q.records(1, 10, max_count=3, max_bytes=10_000)) == 3
    assert len(q.records(1, 10, max_count=10, max_bytes=250)) == 2
    assert len(q.records(1, 10, max_count=10, max_bytes=1)) == 1     # a record bigger than the budget goes alone
    assert q.records(11, 10, max_count=10, max_bytes=1000) == []
    q.close()


def test_reopen_continues_the_sequence_and_keeps_the_acked_mark(tmp_path):
    q = open_queue(tmp_path)
    for i in range(1, 21):
        q.append(payload(i), i)
    q.ack(12)
    epoch = q.epoch
    q.close()
    q = open_queue(tmp_path)
    assert not q.recovery.created and q.epoch == epoch
    assert (q.acked, q.last_seq, q.unacked) == (12, 20, 8)
    assert q.append(b'next', 0) == 21
    assert [r.data for r in q.records(13, 20, 100, 1 << 20)] == [payload(i) for i in range(13, 21)]
    q.close()


def test_a_second_process_cannot_open_the_same_queue(tmp_path):
    q = open_queue(tmp_path)
    with pytest.raises(QueueLocked):
        open_queue(tmp_path)
    q.close()
    open_queue(tmp_path).close()


def test_a_torn_tail_is_cut_at_every_byte_of_the_last_record_and_earlier_records_stay_intact(tmp_path):
    """A crash in the middle of the last append, simulated by cutting the file anywhere inside that record
    (and by a flipped byte in it): the queue reopens with records 1..4 and gives the next record seq 5."""
    q = open_queue(tmp_path / 'src')
    for i in range(1, 6):
        q.append(payload(i), i)
    q.close()
    seg = segments(tmp_path / 'src')[0]
    with open(seg, 'rb') as f:
        whole = f.read()
    start = len(whole) - len(frame(5, 5, payload(5)))
    cases = [whole[:cut] for cut in range(start, len(whole))]
    cases += [whole[:i] + bytes([whole[i] ^ 0x40]) + whole[i + 1:] for i in range(start, len(whole), 7)]
    for n, damaged in enumerate(cases):
        d = tmp_path / f'case{n}'
        d.mkdir()
        os.link(os.path.join(str(tmp_path / 'src'), 'queue.json'), str(d / 'queue.json'))
        with open(str(d / os.path.basename(seg)), 'wb') as f:
            f.write(damaged)
        q = open_queue(d)
        assert q.last_seq == 4 and q.recovery.torn_bytes == len(damaged) - start, n
        assert [r.data for r in q.records(1, 4, 10, 1 << 20)] == [payload(i) for i in range(1, 5)]
        assert os.path.getsize(str(d / os.path.basename(seg))) == start
        assert q.append(b'after', 0) == 5 and q.read(5).data == b'after'
        q.close()


def test_damage_in_an_older_segment_is_reported_not_cut(tmp_path):
    q = open_queue(tmp_path, segment_bytes=200)
    for i in range(1, 20):
        q.append(b'y' * 60, i)
    q.close()
    first = segments(tmp_path)[0]
    with open(first, 'r+b') as f:
        f.seek(SEGMENT_HEADER.size + RECORD_HEADER.size + 3)
        f.write(b'Z')
    with pytest.raises(QueueCorrupt, match='not the newest segment'):
        open_queue(tmp_path)


def test_segments_roll_and_acknowledged_ones_are_compacted(tmp_path):
    q = open_queue(tmp_path, segment_bytes=500)
    for i in range(1, 41):
        q.append(b'z' * 50, i)                       # 74 bytes a record: 7 per segment
    n = len(segments(tmp_path))
    assert n == 6
    q.ack(20)
    left = segments(tmp_path)
    assert len(left) == 4 and int(os.path.basename(left[0])[:-4]) <= 21
    assert [r.seq for r in q.records(21, 40, 100, 1 << 20)] == list(range(21, 41))
    q.ack(40)
    assert len(segments(tmp_path)) == 1                # the newest segment is kept: it carries the sequence
    assert q.unacked == 0 and q.unacked_bytes == 0
    q.close()
    q = open_queue(tmp_path)
    assert (q.acked, q.last_seq) == (40, 40) and q.append(b'a', 0) == 41
    q.close()


def test_acknowledged_records_are_retained_and_the_floor_says_what_is_gone(tmp_path):
    q = DiskQueue(str(tmp_path), 1000, 1 << 20, 500, False, retain_records=10)
    for i in range(1, 41):
        q.append(b'z' * 50, i)                       # 7 records a segment: 1-7, 8-14, 15-21, ...
    q.ack(20)
    assert q.floor == 7 and q.records(8, 9, 10, 1 << 20)[0].seq == 8        # 8..20 kept: 10 acked ones follow 7
    q.ack(40)
    assert q.floor == 28 and q.unacked == 0                                  # whole segments only
    q.close()
    q = DiskQueue(str(tmp_path), 1000, 1 << 20, 500, False, retain_records=10)
    assert (q.floor, q.acked, q.last_seq) == (28, 40, 40)
    q.close()


def test_a_receiver_that_acks_less_gets_everything_after_its_ack_again(tmp_path):
    """A consumer promoted with an older mark acknowledges less than the one before it: the sender goes back
    to its ack (not below the floor) and sends the rest again; the next ack moves on as usual."""
    q = DiskQueue(str(tmp_path), 1000, 1 << 20, 500, False, retain_records=10)
    s = Sender(q, SenderSettings(window=50, batch_records=50, batch_bytes=1 << 20, ack_timeout=1.0, max_backoff=4.0))
    for i in range(1, 31):
        q.append(payload(i), i)
    assert [r.seq for r in s.poll(0.0)] == list(range(1, 31))
    assert s.on_ack(q.epoch, 30, 0.1) == 30 and s.pending == 0 and s.poll(0.2) == []
    s.on_ack(q.epoch, 25, 0.3)                       # a new receiver holds up to 25
    assert (s.base, s.rewinds, s.pending) == (25, 1, 5) and [r.seq for r in s.poll(0.4)] == [26, 27, 28, 29, 30]
    s.on_ack(q.epoch, 30, 0.5)
    assert s.pending == 0 and q.acked == 30
    s.on_ack(q.epoch, 2, 0.6)                        # below what the queue still holds: from the floor on
    assert s.base == q.floor > 2 and s.poll(0.7)[0].seq == q.floor + 1
    q.close()


def test_a_receivers_mark_travels_and_is_checked(tmp_path):
    a = Receiver(str(tmp_path / 'a.json'), fsync=False)
    a.plan(7, 0, [1, 2, 3])
    a.commit(3)
    b = Receiver(str(tmp_path / 'b.json'), fsync=False)
    b.adopt(a.mark())
    assert (b.epoch, b.delivered) == (7, 3) and Receiver(str(tmp_path / 'b.json'), fsync=False).delivered == 3
    assert b.plan(7, 0, [2, 3, 4]).start == 2
    with pytest.raises(ValueError, match='relay.delivered'):
        parse_mark({'epoch': 7, 'delivered': -1, 'retired': []})


def test_losing_the_acked_mark_only_means_resending(tmp_path):
    q = open_queue(tmp_path, segment_bytes=500)
    for i in range(1, 41):
        q.append(b'z' * 50, i)
    q.ack(30)
    q.close()
    os.unlink(str(tmp_path / 'acked.json'))
    q = open_queue(tmp_path)
    # compaction kept the segment holding 29..35, so the queue knows 28 and below were acknowledged
    assert 21 <= q.acked <= 30 and q.last_seq == 40
    q.close()


def test_a_full_queue_refuses_and_counts_and_takes_records_again_after_an_ack(tmp_path):
    q = open_queue(tmp_path, max_records=5)
    assert [q.append(b'r', 0) for _ in range(5)] == [1, 2, 3, 4, 5]
    assert q.append(b'r', 0) is None and q.append(b'r', 0) is None
    assert q.full and q.rejected == 2 and q.last_seq == 5
    q.ack(2)
    assert not q.full and q.append(b'r', 0) == 6
    q.close()
    by_bytes = open_queue(tmp_path / 'b', max_bytes=3 * (RECORD_HEADER.size + 10))
    assert [by_bytes.append(b'0123456789', 0) for _ in range(4)] == [1, 2, 3, None]
    assert by_bytes.full and by_bytes.rejected == 1
    by_bytes.close()


def test_an_ack_ahead_of_the_queue_skips_the_sequence_forward(tmp_path):
    q = open_queue(tmp_path)
    for _ in range(3):
        q.append(b'a', 0)
    s = Sender(q, SenderSettings(window=10, batch_records=10, batch_bytes=1000, ack_timeout=1, max_backoff=4))
    assert s.on_ack(q.epoch, 7, 0.0) == 7 and s.skipped == 1
    assert q.append(b'b', 0) == 8
    q.close()
    q = open_queue(tmp_path)
    assert (q.acked, q.last_seq) == (7, 8)
    q.close()


def test_an_acked_mark_ahead_of_the_disk_skips_on_open(tmp_path):
    """Without fsync a power loss can lose records the receiver already has: their numbers are never reused."""
    q = open_queue(tmp_path)
    for _ in range(5):
        q.append(b'a', 0)
    q.ack(5)
    q.close()
    seg = segments(tmp_path)[0]
    with open(seg, 'r+b') as f:
        f.truncate(SEGMENT_HEADER.size + 2 * len(frame(1, 0, b'a')))      # records 3..5 "lost"
    q = open_queue(tmp_path)
    assert q.recovery.skipped_to == 6 and q.append(b'b', 0) == 6
    q.close()


def test_with_fsync_only_synced_records_are_sendable(tmp_path):
    q = open_queue(tmp_path, fsync=True)
    s = Sender(q, SenderSettings(window=10, batch_records=10, batch_bytes=1000, ack_timeout=1, max_backoff=4))
    q.append(b'a', 0)
    assert s.poll(0.0) == []
    q.sync()
    assert [r.seq for r in s.poll(0.0)] == [1]
    q.close()


# ---------------------------------------------------------------- sender and receiver
def test_sender_windows_times_out_and_backs_off(tmp_path):
    q = open_queue(tmp_path)
    for i in range(25):
        q.append(b'm', 0)
    s = Sender(q, SenderSettings(window=10, batch_records=4, batch_bytes=1000, ack_timeout=1.0, max_backoff=3.0))
    batches = [[r.seq for r in s.poll(0.0)] for _ in range(4)]
    assert batches == [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10], []] and s.in_flight == 10 and s.sent == 10
    assert s.poll(0.99) == []
    assert [r.seq for r in s.poll(1.0)] == [1, 2, 3, 4] and s.timeouts == 1 and s.resent == 4
    assert s.timeout == 2.0
    s.poll(1.0), s.poll(1.0)
    s.poll(3.0)                                       # 2 s: second timeout
    assert s.timeouts == 2 and s.timeout == 3.0       # capped at max_backoff
    assert s.on_ack(q.epoch, 6, 3.5) == 6 and s.timeout == 1.0 and q.acked == 6
    assert s.on_ack(q.epoch + 1, 20, 3.5) == 0 and s.stale_acks == 1 and q.acked == 6
    q.close()


def test_an_ack_without_progress_ends_the_backoff(tmp_path):
    """After an outage the receiver's repeated ack gets through first: the sender resends at once instead of
    waiting out its backed-off timeout."""
    q = open_queue(tmp_path)
    q.append(b'm', 0)
    s = Sender(q, SenderSettings(window=10, batch_records=4, batch_bytes=1000, ack_timeout=1.0, max_backoff=8.0))
    s.poll(0.0)
    for t in (1.0, 3.0, 7.0):                         # timeouts of 1, 2, 4 s: nothing gets through
        assert [r.seq for r in s.poll(t)] == [1]
    assert s.timeout == 8.0 and s.poll(9.0) == []
    assert s.on_ack(q.epoch, 0, 9.0) == 0 and s.timeout == 1.0
    assert [r.seq for r in s.poll(9.0)] == [1] and s.resent == 4
    q.close()


def test_receiver_delivers_in_order_drops_duplicates_and_gaps(tmp_path):
    r = Receiver(str(tmp_path / 's.json'), fsync=False)
    p = r.plan(7, 0, [1, 2, 3])
    assert p.start == 0 and p.ack
    r.commit(3)
    assert r.plan(7, 0, [2, 3, 4, 5]).start == 2 and r.duplicates == 2
    r.commit(5)
    gap = r.plan(7, 0, [8, 9])
    assert gap.start == 2 and gap.ack and r.out_of_order == 2 and r.delivered == 5
    # restart: the mark survives
    r.set_kind(('cnr_msgs/MergedMeasurement', 'abc'))
    r2 = Receiver(str(tmp_path / 's.json'), fsync=False)
    assert (r2.epoch, r2.delivered) == (7, 5) and r2.plan(7, 0, [4, 5, 6]).start == 2
    assert r2.kind == ('cnr_msgs/MergedMeasurement', 'abc')


def test_receiver_switches_to_a_new_epoch_and_never_goes_back(tmp_path):
    r = Receiver(str(tmp_path / 's.json'), fsync=False)
    r.plan(7, 0, [1, 2])
    r.commit(2)
    p = r.plan(9, 0, [1])                  # a new sender queue
    assert p.start == 0 and r.epoch == 9 and r.delivered == 0
    r.commit(1)
    old = r.plan(7, 2, [3])               # a late batch of the old queue
    assert old.start == 1 and not old.ack and r.stale == 1
    assert Receiver(str(tmp_path / 's.json'), fsync=False).retired == [7]


def test_receiver_without_state_starts_at_the_senders_ack(tmp_path):
    r = Receiver(str(tmp_path / 'lost.json'), fsync=False)
    p = r.plan(7, 40, [41, 42])
    assert p.start == 0 and r.delivered == 40
    assert r.plan(7, 40, [38, 39, 40]).start == 3


class Link:
    """One direction of a bad link: messages are lost, duplicated and reordered (random delays), and nothing
    passes during an outage."""

    def __init__(self, rng: random.Random, loss: float, dup: float, max_delay: float) -> None:
        self.rng = rng
        self.loss = loss
        self.dup = dup
        self.max_delay = max_delay
        self.down = False
        self.in_transit: List[Tuple[float, int, object]] = []
        self.n = 0

    def send(self, now: float, item: object) -> None:
        if self.down or self.rng.random() < self.loss:
            return
        copies = 2 if self.rng.random() < self.dup else 1
        for _ in range(copies):
            self.n += 1
            self.in_transit.append((now + self.rng.uniform(0, self.max_delay), self.n, item))

    def arrived(self, now: float) -> List[object]:
        out = [m for m in self.in_transit if m[0] <= now]
        self.in_transit = [m for m in self.in_transit if m[0] > now]
        self.rng.shuffle(out)
        return [m[2] for m in out]


def run_stream(tmp_path, seed: int, records: int, restarts: bool) -> Tuple[List[bytes], Sender]:
    """A producer, a sender, a bad link both ways and a receiver, with outages and (optionally) restarts of
    both ends; returns what the receiver delivered."""
    rng = random.Random(seed)
    settings = SenderSettings(window=rng.choice([5, 20, 50]), batch_records=rng.choice([1, 4, 5]), batch_bytes=400,
                              ack_timeout=0.5, max_backoff=2.0)
    qdir, state = tmp_path / f'q{seed}', str(tmp_path / f'r{seed}.json')
    q = open_queue(qdir, segment_bytes=rng.choice([300, 2000, 1 << 16]))
    sender = Sender(q, settings)
    receiver = Receiver(state, fsync=False)
    data_link = Link(rng, loss=0.2, dup=0.1, max_delay=0.3)
    ack_link = Link(rng, loss=0.2, dup=0.1, max_delay=0.3)
    delivered: List[bytes] = []
    produced = 0
    now = 0.0
    while produced < records or q.unacked:
        now += 0.02
        if produced < records and rng.random() < 0.6:
            produced += 1
            assert q.append(payload(produced), int(now * 1e9)) == produced
        if rng.random() < 0.01:                         # outage start or end
            data_link.down = ack_link.down = not data_link.down
        if produced >= records:
            data_link.down = ack_link.down = False
        if restarts and rng.random() < 0.005:           # sender crash and restart
            q.close()
            q = open_queue(qdir, segment_bytes=q.segment_bytes)
            sender = Sender(q, settings)
        if restarts and rng.random() < 0.005:           # receiver restart (clean: between batches)
            receiver = Receiver(state, fsync=False)
        batch = sender.poll(now)
        if batch:
            data_link.send(now, (q.epoch, q.floor, batch))
        for epoch, acked, recs in data_link.arrived(now):
            plan = receiver.plan(epoch, acked, [r.seq for r in recs])
            delivered.extend(r.data for r in recs[plan.start:])
            if plan.start < len(recs):
                receiver.commit(recs[-1].seq)
            if plan.ack:
                ack_link.send(now, (receiver.epoch, receiver.delivered))
        for epoch, seq in ack_link.arrived(now):
            sender.on_ack(epoch, seq, now)
        assert now < 3600, 'the stream did not finish'
    q.close()
    return delivered, sender


@pytest.mark.parametrize('seed', range(12))
def test_exactly_once_in_order_over_a_bad_link(tmp_path, seed):
    delivered, sender = run_stream(tmp_path, seed, records=300, restarts=False)
    assert delivered == [payload(i) for i in range(1, 301)]
    assert sender.resent > 0                           # the link did lose things


@pytest.mark.parametrize('seed', range(12))
def test_exactly_once_in_order_across_restarts_of_both_ends(tmp_path, seed):
    delivered, _ = run_stream(tmp_path, 100 + seed, records=300, restarts=True)
    assert delivered == [payload(i) for i in range(1, 301)]


def test_a_receiver_crash_between_delivering_and_committing_repeats_at_most_that_batch(tmp_path):
    q = open_queue(tmp_path / 'q')
    for i in range(1, 11):
        q.append(payload(i), 0)
    s = Sender(q, SenderSettings(window=10, batch_records=5, batch_bytes=10_000, ack_timeout=1, max_backoff=2))
    state = str(tmp_path / 'r.json')
    r = Receiver(state, fsync=False)
    out: List[int] = []
    b1 = s.poll(0.0)
    out += [x.seq for x in b1[r.plan(q.epoch, q.acked, [x.seq for x in b1]).start:]]
    r.commit(b1[-1].seq)
    b2 = s.poll(0.0)
    out += [x.seq for x in b2[r.plan(q.epoch, q.acked, [x.seq for x in b2]).start:]]
    r = Receiver(state, fsync=False)                   # crashed before commit(10) and before acking
    b = s.poll(5.0)                                    # ack timeout: resent from 1
    while b:
        p = r.plan(q.epoch, q.acked, [x.seq for x in b])
        out += [x.seq for x in b[p.start:]]
        if p.start < len(b):
            r.commit(b[-1].seq)
        b = s.poll(5.0)
    assert out == list(range(1, 11)) + list(range(6, 11))
    q.close()


# ---------------------------------------------------------------- parameters
def test_the_shipped_config_is_valid_for_both_roles():
    s = Section.from_file(os.path.join(WS, 'config', 'store_forward.yaml'))
    snd, rcv = sf_config.sender_from_section(s), sf_config.receiver_from_section(s)
    assert snd.common.topic('data') == 'store_forward/measurements/data'
    assert snd.stream_dir.endswith('/store_forward/measurements') and os.path.isabs(snd.stream_dir)
    assert rcv.state_path.endswith('/store_forward/measurements.json')


@pytest.mark.parametrize('edit,message', [
    (lambda d: d['sender'].pop('window'), 'sender.window: missing'),
    (lambda d: d.update(stream='a/b'), 'stream: must be a ROS name'),
    (lambda d: d['sender'].update(batch_records=500), 'sender.batch_records: must be <= window'),
    (lambda d: d['sender'].update(max_backoff=0.5), 'sender.max_backoff: must be >= ack_timeout'),
    (lambda d: d['sender'].update(fsync='yes'), 'sender.fsync: expected true or false'),
    (lambda d: d['sender'].pop('retain_records'), 'sender.retain_records: missing'),
])
def test_a_bad_parameter_is_named(edit, message):
    from cnr_params import load_yaml
    data = load_yaml(os.path.join(WS, 'config', 'store_forward.yaml'))
    edit(data)
    with pytest.raises(ConfigError, match=message):
        sf_config.sender_from_section(Section(data, 'test'))
