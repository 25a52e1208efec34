"""local_mapcell_manager's ledger without a master: the migration state (round trip through the wire codec,
bad states refused naming the field, nothing changed), the hand-over between a frozen instance and a standby
that buffered an overlapping suffix of the stream (every measurement stored and published exactly once), a
rollback, a promotion without a state, the buffer bound, and the store's atomic rewrite."""
import json
import os

import pytest

from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import HEADER, HEADER_LINE, format_row, read_tsv
from local_mapcell_manager.core.ledger import (DUPLICATE, OUTSIDE, STORED, Dedup, Ledger, Prepared, Reading,
                                               parse_state, state_newest)
from merger.core.retention import Retention
from local_mapcell_manager.core.store import Draft, MeasurementStore
from migration_manager.core import state as codec

GRID = MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=11, rows=2)


def ledger(tmp_path, name, buffer_size=1000, active=True, warn=None):
    lg = Ledger(GRID, MeasurementStore(str(tmp_path / f'{name}.tsv')), buffer_size,
                warn if warn is not None else (lambda s: None))
    if active:
        lg.activated()
    return lg


def reading(i, t=None, x=None, y=0.5, temp=None):
    return Reading(time=float(i) / 3 if t is None else t, x=(i * 0.37) % 11 if x is None else x, y=y,
                   temperature=22.0 + i * 0.01 if temp is None else temp, pose_time=float(i) / 3 - 0.01, yaw=0.1 * i)


def stream():
    """Readings as the merger would send them, with the awkward cases: two different readings with one stamp,
    a delivered-again duplicate, one out of order, one outside the grid (which still advances the newest)."""
    s = [reading(i) for i in range(1, 30)]
    s.insert(10, reading(10, temp=30.0))                   # same stamp as reading 10, another value
    s.insert(11, reading(10))                              # reading 10 delivered again
    s.insert(15, reading(3))                               # out of order: older than the newest
    s.insert(20, reading(17.5, x=11.5))                    # outside the grid (x > 11)
    s.insert(21, reading(17.5, x=11.5, temp=40.0))         # outside, the same stamp
    s.insert(22, reading(17.5, x=4.2))                     # inside, the same stamp as the outside ones
    return s


def rows(lg):
    return [(m.number, m.time, m.x, m.y, m.temperature, m.cell, m.row, m.col, m.pose_time)
            for m in lg.measurements()]


def lines(lg):
    """The rows as the store writes them (the file's precision)."""
    return [format_row(m) for m in lg.measurements()]


def cells(lg):
    return [(s.visit_count, s.n, s.mean, s.min, s.max, s.last_visit) for s in lg.book.states]


def publish(lg, out):
    """What the node does while active: publish every pending measurement, mark it published."""
    pending = lg.pending()
    out.extend((m.number, m.time, m.temperature, yaw) for m, yaw in pending)
    lg.published(m.number for m, _ in pending)


def wire(state):
    return codec.decode('local_mapcell_manager', codec.encode('local_mapcell_manager', state))


def reference(tmp_path):
    ref = ledger(tmp_path, 'reference')
    for r in stream():
        ref.receive(r)
    return ref


# -- the duplicate rule ---------------------------------------------------------------------------
def test_dedup_keeps_different_readings_of_one_stamp_and_drops_each_again():
    d = Dedup()
    a, b = (1.0, 0.5, 0.5, 22.0), (1.0, 0.5, 0.5, 23.0)
    for k in (a, b):
        assert not d.is_duplicate(k)
        d.add(k)
    assert d.is_duplicate(a) and d.is_duplicate(b)         # the old rule (== newest only) stored `a` again
    assert d.is_duplicate((0.9, 0.5, 0.5, 99.0)) and not d.is_duplicate((1.0, 0.6, 0.5, 22.0))
    d.add((2.0, 0.5, 0.5, 22.0))
    assert d.keys == {(2.0, 0.5, 0.5, 22.0)} and d.is_duplicate(b)


def test_live_outcomes(tmp_path):
    lg = ledger(tmp_path, 'a')
    outcomes = [lg.receive(r)[0] for r in stream()]
    assert outcomes.count(DUPLICATE) == 2 and outcomes.count(OUTSIDE) == 2
    assert outcomes.count(STORED) == len(stream()) - 4 == lg.count
    assert lg.duplicates == 2 and lg.outside == 2
    times = [m.time for m in lg.measurements()]
    assert times == sorted(times)


# -- the state ------------------------------------------------------------------------------------
def test_state_round_trip_through_the_wire(tmp_path):
    a = reference(tmp_path)
    publish(a, [])
    a.receive(reading(40))                                 # stored, not published: handed over as pending
    state = wire(a.state())
    assert set(state) == {'grid', 'measurements', 'newest', 'unpublished', 'duplicates', 'outside'}
    assert list(state['measurements']) == HEADER                       # the store's columns
    assert state['unpublished'] == {'measurement': [a.count], 'yaw': [pytest.approx(4.0)]}

    b = ledger(tmp_path, 'b', active=False)
    b.restore(state)
    assert rows(b) == rows(a) and cells(b) == cells(a)
    assert (b.c.dedup.newest_time, b.c.dedup.keys) == (a.c.dedup.newest_time, a.c.dedup.keys)
    assert (b.duplicates, b.outside) == (a.duplicates, a.outside)
    assert [(m.number, yaw) for m, yaw in b.pending()] == [(a.count, pytest.approx(4.0))]
    assert wire(b.state()) == state
    # the rewritten file: the same rows as the frozen instance's own file, reloaded the same
    with open(a.store.path) as fa, open(b.store.path) as fb:
        assert fb.read() == fa.read()
    assert rows(Ledger(GRID, MeasurementStore(b.store.path), 10)) == [
        (m.number, m.time, m.x, m.y, m.temperature, m.cell, m.row, m.col, m.pose_time)
        for m in read_tsv(a.store.path)]


def test_state_of_an_empty_ledger(tmp_path):
    a = ledger(tmp_path, 'a')
    b = ledger(tmp_path, 'b', active=False)
    b.receive(reading(1))
    b.restore(wire(a.state()))                             # nothing handed over: the buffer is all there is
    assert [m.time for m in b.measurements()] == [reading(1).time]


def bad_states():
    def edit(path, value):
        def f(s):
            d = s
            for k in path[:-1]:
                d = d[k]
            if value is KeyError:
                del d[path[-1]]
            else:
                d[path[-1]] = value(d[path[-1]]) if callable(value) else value
            return s
        return f
    return [
        ('the state', lambda s: [s]),
        ('measurements is missing', edit(['measurements'], KeyError)),
        ('measurements.time is missing', edit(['measurements', 'time'], KeyError)),
        ('measurements.time must be a list', edit(['measurements', 'time'], 'x')),
        ('measurements.x has 1 items', edit(['measurements', 'x'], lambda v: v[:1])),
        ('measurements.temperature[2] must be a finite number', edit(['measurements', 'temperature'],
                                                                   lambda v: v[:2] + ['hot'] + v[3:])),
        ('measurements.time[0] must be a finite number', edit(['measurements', 'time'],
                                                             lambda v: [float('nan')] + v[1:])),
        ('measurements.measurement[1] must be >= 2', edit(['measurements', 'measurement'],
                                                          lambda v: [v[0], v[0]] + v[2:])),
        ('measurements.cell[0] must be an integer', edit(['measurements', 'cell'], lambda v: [True] + v[1:])),
        ('measurements.cell[0] 0 (row', edit(['measurements', 'cell'], lambda v: [0] + v[1:])),
        ('grid', edit(['grid', 'cols'], 12)),
        ('grid.rows is missing', edit(['grid', 'rows'], KeyError)),
        ('newest.time is missing', edit(['newest', 'time'], KeyError)),
        ('newest.time 1.0 is older than a stored measurement', edit(['newest'], {'time': 1.0, 'keys': []})),
        ('newest.keys[0] must be [time, x, y, temperature]', edit(['newest', 'keys'], [[1.0, 2.0]])),
        ('unpublished.measurement[0] 999 is not a stored measurement', edit(['unpublished', 'measurement'],
                                                                           lambda v: [999] + v[1:])),
        ('unpublished.yaw has 0 items', edit(['unpublished', 'yaw'], [])),
        ('duplicates is missing', edit(['duplicates'], KeyError)),
        ('outside must be >= 0', edit(['outside'], -1)),
    ]


@pytest.mark.parametrize('expected,spoil', bad_states(), ids=[b[0] for b in bad_states()])
def test_a_state_that_does_not_fit_is_refused_naming_the_field_and_nothing_changes(tmp_path, expected, spoil):
    a = reference(tmp_path)
    a.receive(reading(40))
    state = spoil(json.loads(json.dumps(a.state())))
    b = ledger(tmp_path, 'b', active=False)
    for r in stream()[:3]:
        b.receive(r)
    before = open(b.store.path).read()
    with pytest.raises(ValueError) as err:
        b.restore(state)
    assert str(err.value).startswith('local_mapcell_manager state: ') and expected in str(err.value), err.value
    assert open(b.store.path).read() == before and b.count == 0 and b.mode == 'buffering' and len(b.buffer) == 3
    with pytest.raises(ValueError):
        parse_state(state, GRID)


# -- the hand-over ---------------------------------------------------------------------------------
def hand_over(tmp_path, j, k, lapse=(), replicas=False):
    """A is active and gets the stream up to k (not publishing at the indices in ``lapse``); B is a standby
    from index j (its subscription connected then); A is frozen after k readings and B promoted with A's state;
    the rest of the stream goes to B only. With ``replicas``, A replicates its state every third reading (a
    whole one every third replica, patches between: the wire of migration_manager), B prepares its store from
    each, and the state handed over is a patch to B's newest replica."""
    s = stream()
    a, b = ledger(tmp_path, 'a'), ledger(tmp_path, 'b', active=False)
    replicator, replica = codec.Replicator('local_mapcell_manager', 3), codec.Replica('local_mapcell_manager')
    prepared = Prepared(GRID, b.store) if replicas else None
    published_a, published_b = [], []
    for i, r in enumerate(s[:k]):
        a.receive(r)
        if i >= j:
            b.receive(r)
        if i not in lapse:
            publish(a, published_a)
        if replicas and i % 3 == 2:
            assert replica.take('a', *replicator.next(a.state()))
            prepared.update(replica.state)
    assert a.freeze()
    if replicas:
        state = replica.resolve('a', replicator.final(a.state(), replica.seq))
    else:
        state = wire(a.state())
    for r in s[k:k + 2]:                                     # between the freeze and the promotion
        a.receive(r)
        b.receive(r)
    replay = b.restore(state, prepared)
    # what a replica held was prepared ahead (checked, filed, written), not parsed again; no draft left
    assert replay.prepared == (None if not replicas or replica.state is None else     # (none came: whole)
                               len(replica.state['measurements']['measurement']))
    assert not [f for f in os.listdir(tmp_path) if '.draft-' in f]
    for r in s[k + 2:k + 4]:                                 # promoted, not active yet
        b.receive(r)
    b.activated()
    publish(b, published_b)
    for r in s[k + 4:]:
        b.receive(r)
        publish(b, published_b)
    return a, b, published_a, published_b


@pytest.mark.parametrize('replicas', [False, True], ids=['state', 'replicas'])
@pytest.mark.parametrize('j,k', [(0, 0), (0, 5), (3, 11), (10, 11), (11, 11), (10, 12), (15, 16), (19, 21), (20, 22),
                                 (21, 23), (5, 30)])
def test_standby_with_an_overlapping_buffer_ends_with_every_measurement_exactly_once(tmp_path, j, k, replicas):
    ref = reference(tmp_path)
    a, b, pa, pb = hand_over(tmp_path, j, k, replicas=replicas)
    assert rows(b) == rows(ref) and cells(b) == cells(ref) and b.c.dedup.keys == ref.c.dedup.keys
    # (a duplicate among the replayed readings is not told from the overlap: the counter is a diagnostic)
    assert b.outside == ref.outside and b.duplicates <= ref.duplicates
    with open(ref.store.path) as fr, open(b.store.path) as fb:
        assert fb.read() == fr.read()
    # published on mapcell_measurements: A until its freeze, B after its activation, each once, in order
    assert pa + pb == [(m.number, m.time, m.temperature, pytest.approx(yaw)) for m, yaw in ref.pending()]
    # the frozen A stored nothing after its freeze: its file holds exactly what it handed over
    assert a.mode == 'buffering' and a.count == len(pa) and rows(a) == rows(ref)[:a.count]
    assert lines(Ledger(GRID, MeasurementStore(a.store.path), 10)) == lines(a)


def test_what_a_lapse_held_back_is_published_by_the_next_instance(tmp_path):
    ref = reference(tmp_path)
    a, b, pa, pb = hand_over(tmp_path, 5, 14, lapse=(11, 12, 13))
    assert rows(b) == rows(ref)
    assert [p[0] for p in pa + pb] == [m.number for m in ref.measurements()]


def test_rollback_promotes_the_frozen_instance_again_with_its_own_state(tmp_path):
    s, ref = stream(), reference(tmp_path)
    a = ledger(tmp_path, 'a')
    for r in s[:12]:
        a.receive(r)
    a.freeze()
    state = wire(a.state())
    for r in s[12:16]:                                       # the target failed meanwhile; A buffers
        a.receive(r)
    a.restore(state)
    a.activated()
    for r in s[16:]:
        a.receive(r)
    assert rows(a) == rows(ref)


def test_promotion_without_a_state_keeps_its_file_and_adds_the_buffer(tmp_path):
    s, ref = stream(), reference(tmp_path)
    first = ledger(tmp_path, 'a')
    for r in s[:8]:
        first.receive(r)
    again = ledger(tmp_path, 'a', active=False)              # respawned: reloads its file, buffers
    assert again.count == 8
    for r in s[6:14]:
        assert again.receive(r) == ('buffered', None)
    assert again.count == 8
    again.activated()
    for r in s[14:]:
        again.receive(r)
    assert lines(again) == lines(ref)


def test_the_buffer_keeps_the_newest_and_warns_once(tmp_path):
    warnings = []
    b = ledger(tmp_path, 'b', buffer_size=5, active=False, warn=warnings.append)
    for i in range(1, 13):
        b.receive(reading(i))
    assert len(warnings) == 1 and 'standby buffer full (5' in warnings[0] and b.buffer_dropped == 7
    assert [r.time for r in b.buffer] == [reading(i).time for i in range(8, 13)]
    b.activated()
    assert [m.time for m in b.measurements()] == [reading(i).time for i in range(8, 13)]
    assert b.mode == 'active' and not b.buffer


# -- recovery from the merger's retention (a failover) ----------------------------------------------
@pytest.mark.parametrize('j,k,m,c', [(5, 12, 20, 24), (0, 10, 25, 25), (11, 11, 30, 33), (12, 20, 21, 21),
                                     (3, 8, 35, 35), (None, 6, 9, 14)])
def test_a_failover_from_a_replicated_state_recovers_what_no_instance_received(tmp_path, j, k, m, c):
    """A is active until the stream's item k (then cut off); its last replicated state was taken after item j
    (None: before any); B subscribes at item m, asks the merger at item c, is promoted with that state and goes
    on: B's store is the one an instance that never moved would have."""
    s, ref = stream(), reference(tmp_path)
    merger = Retention(10000, 1e6)
    a, b = ledger(tmp_path, 'a'), ledger(tmp_path, 'b', active=False)
    state = wire(a.state())
    for i, r in enumerate(s):
        merger.add(r.time, r)
        if i < k:
            a.receive(r)
            if i == j:
                state = wire(a.state())
        if m <= i < c:
            b.receive(r)
        if i + 1 == c:
            break
    since = b.missing_since(state_newest(state))
    assert since is not None, 'the buffer does not reach back to the state: a gap to recover'
    b.recover([r for _, r in merger.since(since)])
    b.restore(state)
    b.activated()
    for r in s[c:]:
        b.receive(r)
    assert rows(b) == rows(ref) and cells(b) == cells(ref)
    # without the recovery the measurements between the state and B's subscription would be missing
    if j is not None and m > j + 2:
        lost = ledger(tmp_path, 'lost', active=False)
        for r in s[m:c]:
            lost.receive(r)
        lost.restore(state)
        lost.activated()
        assert len(rows(lost)) < len(rows(ref))


def test_no_recovery_when_the_buffer_reaches_back_to_the_state(tmp_path):
    s = stream()
    a, b = ledger(tmp_path, 'a'), ledger(tmp_path, 'b', active=False)
    for r in s[:10]:
        a.receive(r)
    for r in s[8:14]:                               # B subscribed before A's newest
        b.receive(r)
    assert b.missing_since(state_newest(a.state())) is None
    assert b.missing_since(None) == 0.0             # nothing stored anywhere: everything retained
    empty = ledger(tmp_path, 'empty', active=False)
    assert empty.missing_since(3.0) == 3.0          # nothing buffered yet


@pytest.mark.parametrize('state', [None, {}, {'newest': None}, {'newest': {'time': 'x'}}, {'newest': {'time': None}},
                                   {'newest': {'time': float('nan')}}, {'newest': {'time': True}}])
def test_state_newest_of_a_malformed_state_is_none(state):
    assert state_newest(state) is None


def test_recover_puts_the_retained_readings_ahead_of_the_buffer_once(tmp_path):
    b = ledger(tmp_path, 'b', buffer_size=6, active=False, warn=(warnings := []).append)
    for i in (5, 6, 7):
        b.receive(reading(i))
    assert b.recover([reading(i) for i in (2, 3, 4, 5, 6)]) == 3
    assert [r.time for r in b.buffer] == [reading(i).time for i in (2, 3, 4, 5, 6, 7)]
    assert b.recover([reading(i) for i in (1, 2)]) == 1 and len(warnings) == 1 and b.buffer_dropped == 1
    assert [r.time for r in b.buffer] == [reading(i).time for i in (2, 3, 4, 5, 6, 7)]


def test_the_merger_retention_keeps_publication_order_within_its_bounds():
    r = Retention(4, 10.0)
    for stamp in (1.0, 2.0, 1.5, 3.0):
        r.add(stamp, f'm{stamp}')
    assert [item for _, item in r.since(1.5)] == ['m2.0', 'm1.5', 'm3.0'] and r.oldest == 1.0
    r.add(4.0, 'm4.0')                              # count bound: the oldest published goes
    assert len(r) == 4 and r.evicted == 1 and r.oldest == 1.5
    r.add(13.0, 'm13.0')                            # age bound: stamped more than 10 s before the newest (3.0 is not)
    assert [item for _, item in r.since(0.0)] == ['m3.0', 'm4.0', 'm13.0'] and r.evicted == 3
    assert r.since(14.0) == []
    with pytest.raises(ValueError):
        Retention(0, 1.0)


# -- the store's rewrite ---------------------------------------------------------------------------
def test_replace_is_atomic(tmp_path, monkeypatch):
    path = str(tmp_path / 'store.tsv')
    lg = ledger(tmp_path, 'store')
    for r in stream()[:5]:
        lg.receive(r)
    os.chmod(path, 0o644)
    ms = lg.measurements()
    lg.store.replace(ms[:2])
    assert open(path).read() == HEADER_LINE + ''.join(format_row(m) for m in ms[:2])
    assert oct(os.stat(path).st_mode & 0o777) == oct(0o644)
    assert os.listdir(tmp_path) == ['store.tsv']             # no temporary file left

    def broken(src, dst):
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(os, 'replace', broken)
    with pytest.raises(OSError):
        lg.store.replace(ms)
    assert open(path).read() == HEADER_LINE + ''.join(format_row(m) for m in ms[:2])
    assert os.listdir(tmp_path) == ['store.tsv']
    # in a restore, the failure is a refusal (ValueError) and the ledger is unchanged
    b = ledger(tmp_path, 'b', active=False)
    monkeypatch.setattr(os, 'replace', broken)
    with pytest.raises(ValueError, match='cannot rewrite the store'):
        b.restore(lg.state())
    assert b.count == 0 and b.mode == 'buffering'


# -- a standby's store prepared from the replicas ------------------------------------------------------
def test_a_prepared_store_that_does_not_fit_the_state_is_dropped_and_the_state_restored_whole(tmp_path):
    a = reference(tmp_path)
    other = ledger(tmp_path, 'other')                       # another instance's content: not a prefix of a's
    for r in stream()[3:9]:
        other.receive(r)
    b = ledger(tmp_path, 'b', active=False)
    prepared = Prepared(GRID, b.store)
    assert prepared.update(wire(other.state())) == other.count
    assert prepared.update(wire(other.state())) == 0        # the same again: nothing to add
    assert prepared.update(wire(a.state())) == a.count      # not an extension: prepared anew
    assert len([f for f in os.listdir(tmp_path) if '.draft-' in f]) == 1
    prepared.update(wire(other.state()))
    replay = b.restore(wire(a.state()), prepared)
    assert replay.prepared is None and rows(b) == rows(a) and cells(b) == cells(a)
    with open(a.store.path) as fa, open(b.store.path) as fb:
        assert fb.read() == fa.read()
    assert not [f for f in os.listdir(tmp_path) if '.draft-' in f]
    assert prepared.measurements == [] and prepared.draft is None     # used up


def test_a_replica_that_does_not_fit_the_grid_is_refused_naming_the_field(tmp_path):
    a = reference(tmp_path)
    b = ledger(tmp_path, 'b', active=False)
    prepared = Prepared(GRID, b.store)
    prepared.update(wire(a.state()))
    bad = wire(a.state())
    bad['measurements']['cell'][-1] = 999
    with pytest.raises(ValueError, match=r'measurements\.cell\[\d+\]'):
        prepared.update(bad)
    assert prepared.measurements == [] and not [f for f in os.listdir(tmp_path) if '.draft-' in f]
    # a refused state leaves the ledger and the prepared store as they were: the next promotion uses it
    prepared.update(wire(a.state()))
    with pytest.raises(ValueError, match=r'measurements\.cell'):
        b.restore(bad, prepared)
    assert b.count == 0 and b.mode == 'buffering' and len(prepared.measurements) == a.count
    assert b.restore(wire(a.state()), prepared).prepared == a.count and rows(b) == rows(a)
    assert not [f for f in os.listdir(tmp_path) if '.draft-' in f]


def test_drafts_of_ended_processes_are_removed_and_live_ones_kept(tmp_path):
    store = MeasurementStore(str(tmp_path / 'store.tsv'))
    live = Draft(store)
    dead = tmp_path / 'store.tsv.draft-999999999-x.tmp'        # no such pid
    dead.write_text('x')
    other = tmp_path / 'other.tsv.draft-999999999-x.tmp'      # another store's
    other.write_text('x')
    assert store.remove_stale_drafts() == [str(dead)]
    assert sorted(os.listdir(tmp_path)) == sorted(['store.tsv', os.path.basename(live.path), other.name])
    live.discard()
    assert not os.path.exists(live.path)
