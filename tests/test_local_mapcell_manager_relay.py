"""local_mapcell_manager as the receiving end of the store-and-forward relay, without ROS: the real disk queue and
go-back-N sender (cnr_store_forward.core), store instances (Ledger + Receiver, core.relay.take_batch) that fail
over from replicated states of every age, migrate with their final state, crash and come back, over a link that
loses, duplicates and reorders both ways: the active store ends with every reading exactly once, in order."""
from __future__ import annotations

import json
import random
from typing import Dict, List, Optional, Tuple

import pytest

from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import read_tsv
from cnr_store_forward.core.queue import DiskQueue
from cnr_store_forward.core.receiver import Receiver
from cnr_store_forward.core.sender import Sender, SenderSettings
from local_mapcell_manager.core.ledger import Ledger, Reading
from local_mapcell_manager.core.relay import mark_path, state_mark, take_batch
from local_mapcell_manager.core.store import MeasurementStore
from test_cnr_store_forward_core import Link

GRID = MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=11, rows=2)


def reading(i: int) -> Reading:
    return Reading(time=1000.0 + i / 3, x=(i * 0.37) % 11, y=0.5, temperature=22.0 + (i % 50) * 0.01,
                   pose_time=1000.0 + i / 3 - 0.01, yaw=0.0)


def encode(i: int) -> bytes:
    return str(i).encode()


def decode(data: bytes) -> Optional[Reading]:
    return reading(int(data.decode()))


class Instance:
    """One store instance: its file, its relay mark next to it, the ledger; active or not."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.ledger = Ledger(GRID, MeasurementStore(path), 100)
        self.relay = Receiver(mark_path(path), fsync=False)
        self.active = False

    def state(self) -> Dict:
        """get_state: the ledger's state and the matching mark (as the node's hook builds it)."""
        s = self.ledger.state()
        s['relay'] = self.relay.mark()
        return json.loads(json.dumps(s))             # (a copy, as it crosses the wire)

    def promote(self, state: Optional[Dict]) -> None:
        if state is not None:
            mark = state_mark(state)
            self.ledger.restore(state)
            self.relay.adopt(mark)
        self.ledger.activated()
        self.active = True

    def freeze(self) -> Dict:
        self.active = False
        self.ledger.freeze()
        return self.state()

    def take(self, epoch: int, floor: int, records) -> Optional[Tuple[int, int]]:
        """A batch arrives: taken only while active; the ack to send, if any."""
        if not self.active:
            return None
        taken = take_batch(self.relay, self.ledger, epoch, floor, [(r.seq, decode(r.data)) for r in records])
        return (self.relay.epoch, self.relay.delivered) if taken.ack else None


def times(inst: Instance) -> List[float]:
    return [round(m.time, 6) for m in inst.ledger.measurements()]


def run(tmp_path, seed: int, records: int = 400) -> Tuple[Instance, Sender, Dict[str, int]]:
    rng = random.Random(seed)
    settings = SenderSettings(window=rng.choice([10, 40]), batch_records=rng.choice([1, 5, 10]), batch_bytes=4000,
                              ack_timeout=0.5, max_backoff=2.0)
    q = DiskQueue(str(tmp_path / 'queue'), 100000, 1 << 24, rng.choice([300, 4000]), False, retain_records=200)
    sender = Sender(q, settings)
    hosts = {h: Instance(str(tmp_path / f'{h}.tsv')) for h in ('robot', 'cloud')}
    active = hosts['cloud']
    active.promote(None)
    replica: Optional[Dict] = active.state()          # the newest state the manager holds
    data = Link(rng, loss=0.1, dup=0.1, max_delay=0.3)
    acks = Link(rng, loss=0.1, dup=0.1, max_delay=0.6)  # acks of an instance cut off may arrive late
    events = dict(failover=0, migration=0, crash=0)
    produced, now, gap_until, pending = 0, 0.0, 0.0, active

    def done() -> bool:                 # the active store holds what the queue holds (its repeated ack goes on)
        return (produced == records and active is not None and active.relay.epoch == q.epoch
                and active.relay.delivered == q.last_seq)
    while not done():
        now += 0.02
        if produced < records and rng.random() < 0.5:
            produced += 1
            q.append(encode(produced), int(now * 1e9))
        if active is not None and rng.random() < 0.05:                 # replicate_period
            replica = active.state()
        if active is not None and produced < records and rng.random() < 0.01:
            other = hosts['robot' if active is hosts['cloud'] else 'cloud']
            kind = rng.choice(['failover', 'migration', 'crash'])
            if kind == 'failover':           # cut off without a freeze: promoted elsewhere from the last replica
                active.active = False
                active, gap_until = None, now + rng.uniform(0.1, 2.0)
                pending = other
            elif kind == 'migration':        # frozen, its final state handed over
                state = active.freeze()
                other.promote(state)
                active, replica = other, other.state()
            else:                            # killed: comes back on its host from its own files, promoted with
                host = 'robot' if active is hosts['robot'] else 'cloud'       # the last replica
                active.active = False
                hosts[host] = Instance(active.path)
                active, gap_until = None, now + rng.uniform(0.1, 2.0)
                pending = hosts[host]
            events[kind] += 1
        if active is None and now >= gap_until:
            pending.promote(replica)
            active = pending
        batch = sender.poll(now)
        if batch:
            data.send(now, (q.epoch, q.floor, batch))
        for epoch, floor, recs in data.arrived(now):
            if active is not None:
                ack = active.take(epoch, floor, recs)
                if ack is not None:
                    acks.send(now, ack)
        if active is not None and rng.random() < 0.1:                   # the repeated ack
            if active.relay.epoch:
                acks.send(now, (active.relay.epoch, active.relay.delivered))
        for epoch, seq in acks.arrived(now):
            sender.on_ack(epoch, seq, now)
        assert now < 3600, 'the stream did not finish'
    q.close()
    return active, sender, events


@pytest.mark.parametrize('seed', range(16))
def test_every_reading_reaches_the_active_store_once_in_order_across_failovers_migrations_and_crashes(
        tmp_path, seed):
    active, sender, events = run(tmp_path, seed)
    expected = [round(reading(i).time, 6) for i in range(1, 401)]
    assert times(active) == expected
    assert [round(m.time, 6) for m in read_tsv(active.path)] == expected          # the file, too
    assert sum(events.values()) > 0


def test_the_runs_do_fail_over_from_stale_replicas_and_rewind_the_sender(tmp_path):
    rewinds = 0
    kinds = set()
    for seed in range(16):
        _active, sender, events = run(tmp_path / str(seed), seed)
        rewinds += sender.rewinds
        kinds |= {k for k, n in events.items() if n}
    assert rewinds > 0 and kinds == {'failover', 'migration', 'crash'}


def test_a_state_without_a_valid_mark_is_refused_naming_the_field(tmp_path):
    inst = Instance(str(tmp_path / 'a.tsv'))
    inst.promote(None)
    state = inst.state()
    del state['relay']
    with pytest.raises(ValueError, match='relay is missing'):
        state_mark(state)
    for bad, field in (({'epoch': -1, 'delivered': 0, 'retired': []}, 'relay.epoch'),
                       ({'epoch': 1, 'delivered': 'x', 'retired': []}, 'relay.delivered'),
                       ({'epoch': 1, 'delivered': 0, 'retired': [True]}, 'relay.retired')):
        with pytest.raises(ValueError, match=field):
            state_mark(dict(state, relay=bad))


def test_the_mark_is_durable_with_the_store_and_never_ahead_of_it(tmp_path):
    """A batch is stored (each row fsync'ed), then the mark is written: a restart from the files has the mark
    of exactly what the file holds, or less (then the relay sends again and the duplicate rule drops)."""
    inst = Instance(str(tmp_path / 'a.tsv'))
    inst.promote(None)
    q = DiskQueue(str(tmp_path / 'q'), 1000, 1 << 20, 4000, False, retain_records=10)
    for i in range(1, 8):
        q.append(encode(i), i)
    assert inst.take(q.epoch, q.floor, q.records(1, 7, 100, 1 << 20)) == (q.epoch, 7)
    again = Instance(inst.path)
    assert (again.relay.epoch, again.relay.delivered) == (q.epoch, 7) and len(times(again)) == 7
    # a mark behind the file (a crash between the rows and the mark): the batch comes again, stored once
    again.relay.adopt({'epoch': q.epoch, 'delivered': 3, 'retired': []})
    again.promote(None)
    assert again.take(q.epoch, q.floor, q.records(4, 7, 100, 1 << 20)) == (q.epoch, 7)
    assert times(again) == [round(reading(i).time, 6) for i in range(1, 8)]


@pytest.mark.parametrize('edit,message', [
    (lambda d: d.pop('relay_stream'), 'relay_stream: missing'),
    (lambda d: d.pop('relay'), 'relay: missing'),
    (lambda d: d['relay']['receiver'].pop('ack_period'), 'relay.receiver.ack_period: missing'),
    (lambda d: d.update(relay_stream='a/b'), 'stream: must be a ROS name'),
])
def test_the_relay_parameters_are_read_and_a_bad_one_is_named(edit, message):
    """What modules.launch loads: config/local_mapcell_manager.yaml, and config/store_forward.yaml in ~relay."""
    import os
    from cnr_params import ConfigError, Section, load_yaml
    from local_mapcell_manager.core.params import read_relay
    ws = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = dict(load_yaml(os.path.join(ws, 'config', 'local_mapcell_manager.yaml')),
                relay=load_yaml(os.path.join(ws, 'config', 'store_forward.yaml')))
    assert read_relay(Section(data, 'test')) is None                      # the shipped default: direct input
    data['relay_stream'] = 'merged_measurements'
    r = read_relay(Section(data, 'test'))
    assert r.common.topic('data') == 'store_forward/merged_measurements/data' and r.ack_period > 0
    edit(data)
    with pytest.raises(ConfigError, match=message):
        read_relay(Section(data, 'test'))
