"""migration_manager's rospy-free core: leases and terms (never two active), the migration state machine
(make-before-break, rollback, failover), the state codec and the configuration."""
import math
import os

import pytest

from cnr_params import ConfigError, Section, load_yaml
from migration_manager.core import state as codec
from migration_manager.core.config import from_section
from migration_manager.core.lease import Answer, Grantor, Holder, TermFilter, instance_id
from migration_manager.core.plan import Migration, Step, Timeouts

D, MARGIN = 0.6, 0.15
TIMEOUTS = Timeouts(start=30.0, freeze=1.0, promote=3.0, replica=2.0)


def grant(g: Grantor, h: Holder, t_request: float, t_grant: float, t_receive: float) -> None:
    nonce = h.request(t_request)
    h.on_answer(g.request(h.instance, h.term, nonce, t_grant))


# ---------------------------------------------------------------------------- leases
def test_a_promoted_instance_is_active_only_after_its_first_granted_renewal():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@cloud')
    term = g.promote('mfg@cloud', 0.0)
    h.promoted(term)
    assert not h.active(0.01)
    grant(g, h, 0.01, 0.05, 0.09)
    assert h.active(0.1) and h.active(0.6) and not h.active(0.61)      # from its request, not the answer


def test_the_holder_lease_always_ends_before_the_grantor_may_promote_another():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@cloud')
    h.promoted(g.promote('mfg@cloud', 0.0))
    grant(g, h, 1.0, 1.3, 1.6)                      # slow link: 300 ms each way
    holder_end = 1.0 + D
    assert not h.active(holder_end)
    assert not g.may_promote(1.3 + D + MARGIN - 1e-6) and g.may_promote(1.3 + D + MARGIN)
    assert holder_end < g.free_at()
    with pytest.raises(ValueError):
        g.promote('mfg@robot', 1.5)


def test_a_standby_knows_whether_the_module_was_ever_promoted_once_it_heard_the_grantor():
    g, standby = Grantor('local_mapcell_manager', D, MARGIN), Holder('local_mapcell_manager', 'local_mapcell_manager@cloud')
    assert not standby.heard                          # nothing known yet: the lmm standby is not ready
    standby.on_answer(Answer('mfg', 3, 'mfg@robot', 0, False, D))
    assert not standby.heard                          # another module's announcement says nothing
    standby.on_answer(g.announcement())
    assert standby.heard and standby.seen == 0        # the mission's first start: never promoted
    g.promote('local_mapcell_manager@robot', 0.0)
    standby.on_answer(g.announcement())
    assert standby.seen == 1                          # a store was active: its input publisher runs


def test_a_late_answer_cannot_extend_a_lease():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@cloud')
    h.promoted(g.promote('mfg@cloud', 0.0))
    nonce = h.request(1.0)
    answer = g.request('mfg@cloud', h.term, nonce, 1.05)
    h.on_answer(answer)                             # delivered 10 s late (queued in an outage)
    assert not h.active(11.0)
    h.on_answer(answer)                             # and again: the nonce is spent
    assert not h.active(1.1) or h.valid_until == 1.0 + D


def test_release_frees_at_once_and_refuses_the_old_term():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@robot')
    h.promoted(g.promote('mfg@robot', 0.0))
    grant(g, h, 0.1, 0.1, 0.1)
    assert g.release('mfg@robot', h.term) and g.may_promote(0.11)
    a = g.request('mfg@robot', h.term, h.request(0.12), 0.12)
    assert not a.granted
    h.on_answer(a)
    assert h.superseded and not h.active(0.13)
    assert not g.release('mfg@robot', 1)            # only the current holder and term


def test_revoke_refuses_renewals_but_waits_for_a_granted_lease_to_run_out():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@cloud')
    h.promoted(g.promote('mfg@cloud', 0.0))
    grant(g, h, 1.0, 1.0, 1.0)
    g.revoke()
    assert not g.request('mfg@cloud', h.term, h.request(1.1), 1.1).granted
    assert not g.may_promote(1.0 + D) and g.may_promote(1.0 + D + MARGIN)


def test_a_superseded_holder_is_never_active_again_until_promoted_anew():
    h = Holder('mfg', 'mfg@cloud')
    h.promoted(1)
    h.on_answer(Answer('mfg', 2, 'mfg@robot', 0, False, D))
    assert h.superseded
    h.on_answer(Answer('mfg', 1, 'mfg@cloud', h.request(0.0), True, D))     # an old grant arrives late
    assert not h.active(0.1)
    with pytest.raises(ValueError):
        h.promoted(2)                               # terms only grow
    h.promoted(3)
    assert not h.superseded


@pytest.mark.parametrize('paths, host_durations', [(1, None), (2, {'robot': 2.0})])
def test_never_two_active_under_random_delays_losses_and_failovers(paths, host_durations):
    """A cloud holder renews over a link with random delays, losses and outages; the grantor fails over to the
    robot whenever the cloud's lease lapses and back when asked, each promotion carrying a pre-grant of the
    target's newest standby request and reaching it late or never: at no sampled instant are both active. Also
    with each cloud request and answer sent over two paths (independent delays and losses; the grantor answers
    the first copy only) and a longer lease for the robot's instance."""
    import random
    rng = random.Random(7)
    g = Grantor('mfg', D, MARGIN, host_durations=host_durations)
    holders = {h: Holder('mfg', instance_id('mfg', h)) for h in ('robot', 'cloud')}
    holders['cloud'].promoted(g.promote('mfg@cloud', 0.0))
    in_flight = []                                  # (deliver_at, kind, payload)
    t, dt = 0.0, 0.01
    both = pregranted_active = 0
    while t < 240.0:
        outage = (int(t) // 10) % 3 == 2            # 10 s out of every 30 s

        def send(name: str, kind: str, payload) -> None:
            for _ in range(1 if name == 'robot' or kind in ('standby', 'promote') else paths):
                delay = 0.0 if name == 'robot' else rng.uniform(0.005, 0.4)
                if name == 'robot' or (not outage and rng.random() > 0.05):
                    in_flight.append((t + delay, kind, (name, delay) + payload))

        for name, h in holders.items():
            if round(t / 0.1) == t / 0.1 or rng.random() < 0.1:
                if h.term and not h.superseded:
                    send(name, 'req', (h.term, h.request(t)))
                elif not h.active(t):                # a standby's request, for a pre-grant
                    send(name, 'standby', (h.request(t),))
        for item in sorted([x for x in in_flight if x[0] <= t], key=lambda x: x[0]):
            in_flight.remove(item)
            _, kind, payload = item
            name, delay = payload[:2]
            if kind == 'req':
                term, nonce = payload[2:]
                if not g.first_receipt(instance_id('mfg', name), nonce):
                    continue                         # the other path's copy: answered already
                a = g.request(instance_id('mfg', name), term, nonce, t)
                for _ in range(1 if name == 'robot' else paths):
                    if name == 'robot' or not outage:
                        late = 0.0 if name == 'robot' else rng.uniform(0.005, 0.4)
                        in_flight.append((t + late, 'ans', (name, late, a)))
            elif kind == 'standby':
                g.standby_request(instance_id('mfg', name), payload[2], t)
            elif kind == 'promote':
                term, nonce, duration = payload[2:]
                try:
                    holders[name].promoted(term, nonce, duration)
                except ValueError:
                    pass                             # a late order for an old term: refused
                pregranted_active += holders[name].active(t)
            else:
                holders[name].on_answer(payload[2])
        # failover to the robot when the cloud lapsed; back to the cloud when the link is good
        holder = g.holder.rpartition('@')[2]
        if holder == 'cloud' and t > g.valid_until and g.valid_until > 0:
            g.revoke()
        if holder == 'robot' and not outage and rng.random() < 0.005:      # a planned move back: freeze, release
            robot = holders['robot']
            robot.superseded, robot.valid_until = True, float('-inf')
            assert g.release('mfg@robot', robot.term)
        if not g.holder and g.may_promote(t):
            target = 'cloud' if not outage and holder != 'cloud' and rng.random() < 0.5 else 'robot'
            term = g.promote(instance_id('mfg', target), t)
            send(target, 'promote', (term,) + g.pregrant(instance_id('mfg', target), t))
        if all(h.active(t) for h in holders.values()):
            both += 1
        t = round(t + dt, 6)
    assert pregranted_active > 5                   # the pre-grants were exercised
    assert both == 0


def test_a_promotion_carrying_a_standby_request_is_active_at_once_and_ends_before_the_grantor_believes():
    g, h = started(), Holder('mfg', 'mfg@cloud')
    nonce = h.request(1.0)                          # sent by the standby at 1.0, received at 1.1
    g.standby_request('mfg@cloud', nonce, 1.1)
    assert g.release('mfg@robot', g.term)
    term = g.promote('mfg@cloud', 1.2)
    assert g.pregrant('mfg@cloud', 1.2) == (nonce, D)
    h.promoted(term, nonce, D)                      # arrives at 1.3
    assert h.active(1.3) and not h.active(1.0 + D)
    assert 1.0 + D < g.free_at() and not g.may_promote(1.2 + D + MARGIN - 1e-6)   # a rollback waits it out


def test_no_pregrant_from_a_stale_or_unknown_standby_request():
    g = started()
    g.standby_request('mfg@cloud', 7, 1.0)
    assert g.release('mfg@robot', g.term)
    g.promote('mfg@cloud', 1.0 + D)                 # the request is a lease duration old
    assert g.pregrant('mfg@cloud', 1.0 + D) == (0, D) and g.may_promote(1.0 + D)
    h = Holder('mfg', 'mfg@cloud')                  # a restarted process: it never sent that nonce
    h.promoted(g.term, 7, D)
    assert not h.active(1.0 + D)
    g2 = started()
    g2.standby_request('mfg@cloud', 9, 0.5)
    assert g2.pregrant('mfg@cloud', 0.5) == (0, D)  # not the holder: nothing granted
    a, b = Holder('mfg', 'mfg@robot'), Holder('mfg', 'mfg@robot')
    assert a.request(0.0) != b.request(0.0)         # nonces of two processes differ


def test_a_lease_s_length_follows_the_holder_s_host_and_every_answer_carries_it():
    g = Grantor('mfg', D, MARGIN, host_durations={'robot': 2.0})
    robot, cloud = Holder('mfg', 'mfg@robot'), Holder('mfg', 'mfg@cloud')
    robot.promoted(g.promote('mfg@robot', 0.0))
    grant(g, robot, 1.0, 1.1, 1.1)
    assert robot.active(2.99) and not robot.active(3.0)              # its request + 2.0
    assert g.free_at() == pytest.approx(1.1 + 2.0 + MARGIN)
    assert g.release('mfg@robot', robot.term)
    cloud.promoted(g.promote('mfg@cloud', 4.0))
    grant(g, cloud, 5.0, 5.05, 5.1)
    assert cloud.active(5.59) and not cloud.active(5.6)               # its request + D
    assert g.free_at() == pytest.approx(5.05 + D + MARGIN)
    nonce = robot.request(6.0)                      # the robot's standby request: a pre-grant of its own length
    g.standby_request('mfg@robot', nonce, 6.0)
    g.revoke()
    g.promote('mfg@robot', 6.1)
    assert g.pregrant('mfg@robot', 6.1) == (nonce, 2.0)
    assert g.free_at() == pytest.approx(6.1 + 2.0 + MARGIN)
    with pytest.raises(ValueError):
        Grantor('mfg', D, MARGIN, host_durations={'robot': 0.0})


def test_a_request_s_copy_over_another_path_is_told_from_a_new_request():
    g, h = Grantor('mfg', D, MARGIN), Holder('mfg', 'mfg@cloud')
    h.promoted(g.promote('mfg@cloud', 0.0))
    first, second = h.request(1.0), h.request(1.1)
    assert g.first_receipt('mfg@cloud', second)     # the paths deliver in any order
    assert g.first_receipt('mfg@cloud', first)
    assert not g.first_receipt('mfg@cloud', first) and not g.first_receipt('mfg@cloud', second)
    assert g.first_receipt('mfg@robot', first)      # another instance's nonce is its own
    answer = g.request('mfg@cloud', h.term, second, 1.15)
    h.on_answer(answer)
    h.on_answer(answer)                             # the answer's copy over the other path changes nothing
    assert h.active(1.69) and not h.active(1.71)
    for n in range(Grantor.RECEIPTS + 1):           # only the newest are remembered
        g.first_receipt('mfg@cloud', 1000 + n)
    assert len(g.receipts) == Grantor.RECEIPTS and g.first_receipt('mfg@cloud', 1000)


def test_failover_after_a_cut_takes_the_lease_plus_the_margin_at_most(workspace):
    """The configured figures: a cut-off cloud instance is replaced within duration + margin of its last
    renewal's receipt (<= 1 s after the cut, with time to spare for the promotion), its own lease ends before,
    and an instance on the robot keeps a longer lease, renewed less often."""
    cfg = from_section(Section(load_yaml(os.path.join(workspace, 'config', 'migration.yaml')), 'config/migration.yaml'))
    lease = cfg.lease
    g = lease.grantor('mfg', cfg.authority)
    h = Holder('mfg', 'mfg@cloud')
    h.promoted(g.promote('mfg@cloud', 0.0))
    t = 0.0
    while t < 10.0:                                  # renewals every renew_period, 50 ms each way
        h.on_answer(g.request('mfg@cloud', h.term, h.request(t), t + 0.05))
        t = round(t + lease.renew_period, 6)
    cut = t - lease.renew_period + 0.05              # the link goes just after the last request arrived
    assert g.free_at() - cut <= lease.duration + lease.margin <= 0.8
    assert not h.active(g.free_at() - lease.margin)
    assert lease.paths_on('cloud', cfg.authority) >= 2 and lease.paths_on('robot', cfg.authority) == 1
    assert g.duration_of('mfg@robot') > lease.duration
    assert lease.renew_period_on('robot', cfg.authority) >= lease.renew_period
    assert set(cfg.hot_standby) >= {'local_mapcell_manager', 'global_goal_manager', 'mfg'}


def test_term_filter_accepts_only_the_current_holder():
    f = TermFilter()
    assert f.accept('move_base', 'move_base@cloud')           # never announced: unmanaged
    f.on_answer(Answer('move_base', 3, 'move_base@cloud', 0, False, D))
    assert f.accept('move_base', 'move_base@cloud') and not f.accept('move_base', 'move_base@robot')
    f.on_answer(Answer('move_base', 2, 'move_base@robot', 0, False, D))     # older: ignored
    assert f.accept('move_base', 'move_base@cloud')
    f.on_answer(Answer('move_base', 4, '', 0, False, D))     # between holders: nobody
    assert not f.accept('move_base', 'move_base@cloud')


# ---------------------------------------------------------------------------- migrations
def started(module='mfg', host='robot'):
    g = Grantor(module, D, MARGIN)
    g.promote(instance_id(module, host), 0.0)
    g.request(instance_id(module, host), g.term, 1, 0.0)
    return g


def test_cold_migration_is_make_before_break():
    g = started()
    m = Migration('mfg', 'robot', 'cloud', 'cold', TIMEOUTS, g, 1.0)
    assert m.begin(1.0, target_standby_ready=False) == [('start_standby', 'cloud', None)]
    assert m.step is Step.STARTING and g.holder == 'mfg@robot'          # the source keeps working meanwhile
    assert m.target_ready(3.0) == [('freeze', 'robot', 1)]
    actions = m.frozen(3.01, b'state')
    assert actions == [('promote', 'cloud', (3, b'state'))] and g.holder == 'mfg@cloud'
    assert m.target_active(3.2, 3) == [('retire', 'robot', 'cold')]
    assert m.step is Step.DONE and math.isclose(m.downtime, 0.19)


def test_hot_migration_with_a_ready_standby_freezes_at_once():
    g = started()
    m = Migration('mfg', 'robot', 'cloud', 'hot', TIMEOUTS, g, 1.0)
    assert m.begin(1.0, target_standby_ready=True) == [('freeze', 'robot', 1)]


def test_a_ready_standby_without_a_replica_of_the_source_is_waited_for_a_bounded_time():
    """A standby started moments ago (a hot migration back right after one there, or a cold clone) holds no
    replica of the source yet: the freeze waits, at most timeouts.replica, until it does, so that the final state
    comes as a patch to it and not whole (the store's thousands of measurements); past the bound it goes whole."""
    m = Migration('mfg', 'robot', 'cloud', 'hot', TIMEOUTS, started(), 1.0)
    assert m.begin(1.0, True, holds_replica=False) == [] and m.step is Step.STARTING
    assert 'waiting for it to hold a replica of mfg@robot' in m.events[-1].message
    assert m.target_ready(1.5, holds_replica=False) == []
    assert m.target_ready(1.6, holds_replica=True) == [('freeze', 'robot', 1)] and m.step is Step.FREEZING
    late = Migration('mfg', 'robot', 'cloud', 'cold', TIMEOUTS, started(), 1.0)
    assert late.begin(1.0, False) == [('start_standby', 'cloud', None)]
    assert late.target_ready(5.0, holds_replica=False) == []
    assert late.target_ready(5.0 + TIMEOUTS.replica - 0.01, holds_replica=False) == []
    assert late.target_ready(5.0 + TIMEOUTS.replica, holds_replica=False) == [('freeze', 'robot', 1)]
    assert 'without a replica: the whole state goes' in late.events[-2].message


def test_a_target_that_does_not_start_is_rolled_back_and_the_source_never_stopped():
    g = started()
    m = Migration('mfg', 'robot', 'cloud', 'cold', TIMEOUTS, g, 0.0)
    m.begin(0.0, False)
    assert m.tick(29.0) == []
    assert m.tick(30.1) == [('stop', 'cloud', None)]
    assert m.step is Step.ROLLED_BACK and g.holder == 'mfg@robot' and g.term == 1


def test_a_target_that_crashes_after_the_freeze_gives_the_module_back_to_the_source():
    g = started()
    m = Migration('mfg', 'robot', 'cloud', 'cold', TIMEOUTS, g, 0.0)
    m.begin(0.0, True)
    m.frozen(0.1, b's')
    term = m.term
    g.request('mfg@cloud', term, 5, 0.2)          # it was granted once, then crashed
    actions = m.target_failed(0.3, 'crashed')
    assert actions == [('stop', 'cloud', None)] and m.step is Step.ROLLING_BACK
    assert m.tick(0.2 + D) == []                  # its lease may still run
    actions = m.tick(0.2 + D + MARGIN)
    assert actions == [('promote', 'robot', (term + 2, None))] and m.step is Step.ROLLED_BACK   # keeps its own
    assert g.holder == 'mfg@robot'


def test_an_unreachable_source_is_replaced_only_after_its_lease_ran_out():
    g = Grantor('mfg', D, MARGIN)
    g.promote('mfg@cloud', 0.0)
    g.request('mfg@cloud', 1, 1, 10.0)            # last renewal granted at 10.0: valid until 10.6
    m = Migration('mfg', 'cloud', 'robot', 'hot', TIMEOUTS, g, 10.1)
    m.replicated = b'replicated'
    assert m.begin(10.1, True) == [('freeze', 'cloud', 1)]
    assert m.tick(11.0) == []                     # freeze deadline 11.1 not reached
    assert m.tick(11.2) == [('promote', 'robot', (3, b'replicated'))]   # lease 10.6 + 0.15 already over
    assert m.state_source == 'replicated' and math.isclose(m.frozen_at, 10.75)


def test_failover_skips_the_freeze_and_waits_for_the_lease():
    g = Grantor('mfg', D, MARGIN)
    g.promote('mfg@cloud', 0.0)
    g.request('mfg@cloud', 1, 1, 10.0)
    m = Migration('mfg', 'cloud', 'robot', 'hot', TIMEOUTS, g, 10.61, failover=True)
    assert m.begin(10.61, True, holds_replica=False) == []         # no freeze: no replica waited for
    assert m.step is Step.WAITING_LEASE
    assert m.tick(10.7) == []
    assert m.tick(10.75)[0][0] == 'promote'


def test_a_lost_instance_on_the_robot_is_recovered_by_its_restarted_standby_after_its_lease():
    """The robot's own active instance exited (its agent restarted it as a standby): a failover on the same host
    promotes the standby with the last replicated state once the old lease ran out, retires nothing, and a
    failed recovery stops nothing (the agent keeps the host's instance)."""
    g = Grantor('mfg', D, MARGIN)
    g.promote('mfg@robot', 0.0)
    g.request('mfg@robot', 1, 1, 10.0)            # its last renewal: valid until 10.6
    with pytest.raises(ValueError):
        Migration('mfg', 'robot', 'robot', 'hot', TIMEOUTS, g, 10.7)      # an order to where it is
    m = Migration('mfg', 'robot', 'robot', 'hot', TIMEOUTS, g, 10.7, failover=True)
    m.replicated = b'replicated'
    assert m.recovery and m.begin(10.7, True) == [] and m.step is Step.WAITING_LEASE
    actions = m.tick(10.76)
    assert actions == [('promote', 'robot', (m.term, b'replicated'))] and g.holder == 'mfg@robot'
    assert m.term > 1 and m.target_active(10.8, m.term) == [] and m.step is Step.DONE     # nothing retired

    failed = Migration('mfg', 'robot', 'robot', 'hot', TIMEOUTS, g, 20.0, failover=True)
    failed.begin(20.0, True)
    failed.tick(20.0)
    assert failed.target_failed(20.1, 'promote refused') == [] and failed.step is Step.FAILED


def test_first_start_has_no_source():
    g = Grantor('mfg', D, MARGIN)
    m = Migration('mfg', '', 'robot', 'cold', TIMEOUTS, g, 0.0)
    m.begin(0.0, False)
    assert m.target_ready(2.0, holds_replica=False) == [('promote', 'robot', (1, None))]   # nothing to wait for
    assert m.target_active(2.1, 1) == [] and m.step is Step.DONE


def test_a_migration_to_where_the_module_is_is_refused():
    with pytest.raises(ValueError):
        Migration('mfg', 'robot', 'robot', 'cold', TIMEOUTS, started(), 0.0)
    with pytest.raises(ValueError):
        Migration('mfg', 'robot', 'cloud', 'warm', TIMEOUTS, started(), 0.0)


# ---------------------------------------------------------------------------- codec and config
def test_state_round_trip_and_foreign_state():
    data = codec.encode('mfg', {'cell': 3, 'mean': math.nan, 'checked': [1, 2]})
    back = codec.decode('mfg', data)
    assert back['cell'] == 3 and math.isnan(back['mean']) and back['checked'] == [1, 2]
    with pytest.raises(codec.StateError, match='made by'):
        codec.decode('move_base', data)
    with pytest.raises(codec.StateError):
        codec.decode('mfg', b'garbage')



def _store(n):
    """A local_mapcell_manager-like state: columns that grow, bookkeeping that changes."""
    return {'grid': {'cols': 10, 'rows': 3}, 'measurements': {'time': [float(i) for i in range(n)],
                                                              'cell': [i % 30 for i in range(n)]},
            'newest': {'time': float(n - 1), 'keys': [[n - 1, 1]]}, 'unpublished': [n - 1], 'duplicates': n // 7}


def test_a_patch_turns_its_base_into_the_new_state_and_holds_only_what_changed():
    import random
    base, new = _store(3000), _store(3012)
    new['grid']['extra'] = [1, 2]                        # a key added
    del new['duplicates']                               # a key removed
    new['unpublished'] = [5]                            # a list that did not only grow
    p = codec.diff(base, new)
    assert codec.patch(base, p) == new
    assert p['{']['measurements']['{']['time'] == {'+': [float(i) for i in range(3000, 3012)]}
    assert 'grid' in p['{'] and 'cols' not in p['{']['grid']['{'] and p['-'] == ['duplicates']
    assert codec.patch(new, codec.diff(new, base)) == base            # and back (the lists shrink: replaced)
    assert base == _store(3000)                                       # the base is not changed
    whole, delta = codec.encode('local_mapcell_manager', new), codec.encode_patch('local_mapcell_manager', 7, p)
    assert len(delta) * 20 < len(whole)
    assert codec.decode_any('local_mapcell_manager', delta) == (7, p)
    with pytest.raises(codec.BaseMissing, match=codec.BASE_MISSING):
        codec.decode('local_mapcell_manager', delta)                  # a patch alone is not a state
    rng = random.Random(3)                                            # random JSON values, both ways
    def value(depth):
        kind = rng.randrange(5) if depth < 3 else 0
        if kind == 0:
            return rng.choice([None, True, rng.random(), rng.randrange(9), 'x'])
        if kind in (1, 3):
            return [value(depth + 1) for _ in range(rng.randrange(4))]
        return {str(rng.randrange(5)): value(depth + 1) for _ in range(rng.randrange(4))}
    for _ in range(300):
        a, b = value(0), value(0)
        if rng.random() < 0.3 and isinstance(a, list):
            b = a + [value(2)]
        assert codec.patch(a, codec.diff(a, b)) == b
    with pytest.raises(codec.StateError, match=r'state\.k: appends to a dict'):
        codec.patch({'k': {}}, {'{': {'k': {'+': [1]}}})


def test_replicas_are_patches_between_keyframes_and_a_receiver_that_missed_one_waits_for_the_next():
    src = codec.Replicator('local_mapcell_manager', keyframe_every=3)
    rx, late = codec.Replica('local_mapcell_manager'), codec.Replica('local_mapcell_manager')
    msgs = [src.next(_store(n)) for n in (10, 11, 12, 13, 14, 15)]
    assert [(seq, base) for seq, base, _ in msgs] == [(1, 0), (2, 1), (3, 2), (4, 0), (5, 4), (6, 5)]
    for i, (seq, base, data) in enumerate(msgs):
        assert rx.take('lmm@cloud', seq, base, data)
        assert rx.state == _store(10 + i) and rx.seq_of('lmm@cloud') == seq and rx.seq_of('lmm@robot') == 0
        if i >= 1:                                     # joined after the first keyframe: waits for the next
            assert late.take('lmm@cloud', seq, base, data) == (i >= 3)
    assert late.state == _store(15)
    # a freeze: the final state as a patch to the replica the receiver holds, resolved by it
    final = src.final(_store(17), base_seq=6)
    assert codec.decode_any('local_mapcell_manager', final)[0] == 6
    assert rx.resolve('lmm@cloud', final) == _store(17)
    with pytest.raises(codec.BaseMissing):
        rx.resolve('lmm@robot', final)                 # another instance's replica 6 is not this one
    assert rx.resolve('lmm@cloud', src.final(_store(17), base_seq=5)) == _store(17)   # one behind: still held
    assert codec.decode_any('local_mapcell_manager', src.final(_store(17), base_seq=1))[0] == 0   # not kept
    assert codec.decode_any('local_mapcell_manager', src.final(_store(17), base_seq=0))[0] == 0
    src.want_keyframe = True                           # a new standby asked for a base
    assert src.next(_store(18))[1] == 0
    rx.reset()
    with pytest.raises(codec.BaseMissing):
        rx.resolve('lmm@cloud', src.final(_store(19), base_seq=7))
    with pytest.raises(codec.StateError, match='says base'):
        rx.take('lmm@cloud', 9, 3, codec.encode('local_mapcell_manager', _store(1)))

def test_config_from_the_workspace_and_errors_name_the_field(workspace):
    data = load_yaml(os.path.join(workspace, 'config', 'migration.yaml'))
    cfg = from_section(Section(data, 'config/migration.yaml'))
    assert cfg.other('robot') == 'cloud' and 'mfg' in cfg.modules and cfg.lease.renew_period < cfg.lease.duration
    bad = dict(data, lease=dict(data['lease'], renew_period=data['lease']['duration']))
    with pytest.raises(ConfigError, match='lease.renew_period'):
        from_section(Section(bad, 'config/migration.yaml'))
    bad = dict(data, hot_standby='mfg')
    with pytest.raises(ConfigError, match='hot_standby'):
        from_section(Section(bad, 'config/migration.yaml'))
    for key in ('authority_renew_period', 'paths'):
        with pytest.raises(ConfigError, match=f'lease.{key}'):
            from_section(Section(dict(data, lease={k: v for k, v in data['lease'].items() if k != key}),
                                 'config/migration.yaml'))
    bad = dict(data, lease=dict(data['lease'], authority_renew_period=data['lease']['authority_duration']))
    with pytest.raises(ConfigError, match='lease.authority_renew_period'):
        from_section(Section(bad, 'config/migration.yaml'))
    with pytest.raises(ConfigError, match='lease.paths'):
        from_section(Section(dict(data, lease=dict(data['lease'], paths=0)), 'config/migration.yaml'))
    assert cfg.dormant == {'move_base': ('robot',)}
    fewer = from_section(Section(dict(data, modules=['mfg']), 'config/migration.yaml'))
    assert fewer.dormant == {}                  # a run managing fewer modules ignores the others' entries
    assert fewer.hot_standby == ('mfg',)
    for dormant, field in (({'mfg': ['moon']}, 'mfg'), ({'mfg': 'robot'}, 'mfg'), (['move_base'], 'must map')):
        with pytest.raises(ConfigError, match=f'dormant.*{field}'):
            from_section(Section(dict(data, dormant=dormant), 'config/migration.yaml'))
    assert cfg.replicate_period_authority >= cfg.replicate_period
    missing = {k: v for k, v in data.items() if k != 'replicate_period_authority'}
    with pytest.raises(ConfigError, match='replicate_period_authority'):
        from_section(Section(missing, 'config/migration.yaml'))
    assert cfg.replicate_keyframe_every >= 1
    with pytest.raises(ConfigError, match='replicate_keyframe_every'):
        from_section(Section(dict(data, replicate_keyframe_every=0), 'config/migration.yaml'))
    bad = dict(data, control_nice=-21)
    with pytest.raises(ConfigError, match='control_nice'):
        from_section(Section(bad, 'config/migration.yaml'))
    assert cfg.timeouts.replica >= 0
    with pytest.raises(ConfigError, match='timeouts.replica'):
        from_section(Section(dict(data, timeouts=dict(data['timeouts'], replica=-1.0)), 'config/migration.yaml'))
    del data['timeouts']
    with pytest.raises(ConfigError, match='timeouts'):
        from_section(Section(data, 'config/migration.yaml'))


def test_the_control_plane_priority_is_given_per_thread():
    """The calling thread gets the nice value, once; the process's other threads keep theirs. (A positive
    value, which needs no privilege, stands in for the configured one.)"""
    import threading
    from cnr_runtime.priority import Elevator, thread_nice
    warnings = []
    main_nice = thread_nice(threading.get_native_id())
    seen = {}

    def protocol_thread():
        e = Elevator(main_nice + 3, warnings.append)
        e.this_thread()
        e.this_thread()
        seen['nice'] = thread_nice(threading.get_native_id())
    t = threading.Thread(target=protocol_thread)
    t.start()
    t.join()
    assert seen['nice'] == main_nice + 3 and not warnings
    assert thread_nice(threading.get_native_id()) == main_nice
    Elevator(0, warnings.append).this_thread()          # 0: left as it is
    assert thread_nice(threading.get_native_id()) == main_nice and not warnings


BOOST_SCRIPT = r"""
import threading, time, sys
from cnr_runtime.priority import Elevator, thread_nice
from cnr_harness import wait_until
gate, tids = threading.Event(), {}
def worker(name):
    tids[name] = threading.get_native_id()
    gate.wait()
e = Elevator(-5, lambda s: print('WARN', s))
protocol = threading.Thread(target=lambda: (e.this_thread(), worker('protocol')))
module = threading.Thread(target=worker, args=('module',))
protocol.start(); module.start()
wait_until(lambda: len(tids) == 2, 5, 'threads')
main = threading.get_native_id()
e.boost(0.4)
during = {n: thread_nice(t) for n, t in tids.items()}
during['main'] = thread_nice(main)
late = threading.Thread(target=worker, args=('late',))          # created during the boost: inherits it
late.start()
wait_until(lambda: 'late' in tids, 5, 'late thread')
during['late'] = thread_nice(tids['late'])
e.boost(0.4)                                                    # extends it
wait_until(lambda: thread_nice(main) == 0, 5, 'the boost over')
after = {n: thread_nice(t) for n, t in tids.items()}
after['main'] = thread_nice(main)
print(sorted(during.items()), sorted(after.items()))
gate.set()
"""


@pytest.mark.skipif(os.geteuid() != 0, reason='a negative nice value needs root (CAP_SYS_NICE)')
def test_a_boost_gives_every_thread_the_control_nice_for_a_while_then_their_own_back(workspace):
    """Elevator.boost (a promotion's promotion_boost), in a process of its own: every thread at the value, a
    thread created meanwhile too; then each its own back, the protocol thread elevated for good stays."""
    import subprocess
    out = subprocess.run(['/usr/bin/python3', '-c', BOOST_SCRIPT], capture_output=True, text=True, timeout=60,
                         env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == ("[('late', -5), ('main', -5), ('module', -5), ('protocol', -5)] "
                                  "[('late', 0), ('main', 0), ('module', 0), ('protocol', -5)]"), out.stdout


# ---------------------------------------------------------------------------- the configured rule
def rule(workspace):
    from migration_manager.core.rule import PlacementRule, rule_from_section
    data = load_yaml(os.path.join(workspace, 'config', 'migration.yaml'))
    s = Section(data, 'config/migration.yaml')
    cfg = from_section(s)
    return PlacementRule(rule_from_section(s.section('rule'), cfg.modules, cfg.hosts, cfg.authority))


def test_rule_offloads_on_a_good_link_after_the_dwell_and_onloads_when_it_is_bad(workspace):
    r = rule(workspace)
    c = r.cfg
    on_robot = {m: 'robot' for m in c.modules}
    r.observe(0.0, True, c.good_rtt / 2, 0.0)
    assert r.orders(c.dwell - 0.1, on_robot) == []                       # not for long enough yet
    assert r.orders(c.dwell + 0.1, on_robot) == [(m, 'cloud') for m in c.modules]
    for m in c.modules:
        r.moved(m, c.dwell + 0.1)
    on_cloud = {m: 'cloud' for m in c.modules}
    r.observe(10.0, True, (c.good_rtt + c.bad_rtt) / 2, 0.0)           # in the band: stay
    assert r.orders(10.0 + c.dwell + 1, on_cloud) == []
    r.observe(20.0, False, math.nan, 1.0)                                # peer lost
    assert r.orders(20.0 + c.dwell + 0.1, on_cloud) == [(m, 'robot') for m in c.modules]   # budget ignored


def test_rule_budget_limits_moves_to_the_cloud(workspace):
    r = rule(workspace)
    c = r.cfg
    m = c.modules[0]
    r.moved(m, 0.0)
    r.observe(0.0, True, c.good_rtt / 2, 0.0)
    assert c.dwell + 0.1 < c.min_interval
    assert r.orders(c.dwell + 0.1, {m: 'robot'}) == []                  # moved too recently
    assert r.orders(c.min_interval + 0.1, {m: 'robot'}) == [(m, 'cloud')]
    assert r.orders(c.min_interval + 0.1, {m: ''}) == []                # migrating: no order


def test_rule_config_errors_name_the_field(workspace):
    from migration_manager.core.rule import rule_from_section
    data = load_yaml(os.path.join(workspace, 'config', 'migration.yaml'))
    data['rule']['bad']['rtt_above'] = 0.01
    s = Section(data, 'config/migration.yaml')
    cfg = from_section(s)
    with pytest.raises(ConfigError, match='rule.bad.rtt_above'):
        rule_from_section(s.section('rule'), cfg.modules, cfg.hosts, cfg.authority)


def test_the_announcement_of_a_promotion_may_arrive_before_the_order():
    h = Holder('mfg', 'mfg@cloud')
    h.on_answer(Answer('mfg', 3, 'mfg@cloud', 0, False, D))     # the manager announced term 3 for this instance
    h.promoted(3)                                               # ... then the promotion order arrives
    assert h.term == 3 and not h.superseded
    other = Holder('mfg', 'mfg@robot')
    other.on_answer(Answer('mfg', 3, 'mfg@cloud', 0, False, D))
    with pytest.raises(ValueError):
        other.promoted(3)                                       # term 3 belongs to another instance
