"""multimaster_bridge without a master: sync rules, wire format, heartbeat estimation, configuration."""
import math
import os

import pytest

from cnr_params import ConfigError, Section
from multimaster_bridge.core import config, protocol, sync
from multimaster_bridge.core.heartbeat import LinkEstimator

ALL = sync.Filter(['*'])


def snapshot(pubs=None, subs=None, services=None, types=None, nodes=None, service_apis=None):
    snap = sync.Snapshot(pubs={k: set(v) for k, v in (pubs or {}).items()},
                         subs={k: set(v) for k, v in (subs or {}).items()},
                         services=dict(services or {}), types=dict(types or {}),
                         service_apis=dict(service_apis or {}))
    snap.nodes = dict(nodes) if nodes is not None else {n: f'http://h:{1000 + i}/'
                                                        for i, n in enumerate(sorted(snap.node_names()))}
    return snap


def test_filter_denies_by_default_and_deny_beats_allow():
    assert not sync.Filter().passes('/chatter')
    f = sync.Filter(['/move_base/*', '/tf'], ['*/set_logger_level'])
    assert f.passes('/move_base/goal') and f.passes('/tf') and not f.passes('/tf_static')
    assert not f.passes('/move_base/set_logger_level')


def test_export_skips_own_proxies_filtered_names_and_unknown_nodes():
    snap = snapshot(pubs={'/chatter': ['/talker', '/cloud/talker'], '/secret': ['/talker']},
                    subs={'/chatter': ['/listener']}, types={'/chatter': 'std_msgs/String', '/secret': 'std_msgs/String'},
                    services={'/add': '/adder', '/cloud_srv': '/cloud/x'},
                    service_apis={'/add': 'rosrpc://h:1', '/cloud_srv': 'rosrpc://h:2'})
    state = sync.export_state(snap, {'/cloud/talker', '/cloud/x'}, sync.Filter(['/chatter']), ALL,
                              {'/add': 2.0}, {'std_msgs/String': 'abc'})
    assert state['pubs'] == {'/chatter': ['/talker']}
    assert state['subs'] == {'/chatter': ['/listener']}
    assert state['srvs'] == {'/add': ['/adder', 'rosrpc://h:1', 2.0]}
    assert set(state['nodes']) == {'/talker', '/listener', '/adder'}
    assert state['md5'] == {'std_msgs/String': 'abc'}
    # the digest ignores service ages, which change on every poll
    again = sync.export_state(snap, {'/cloud/talker', '/cloud/x'}, sync.Filter(['/chatter']), ALL,
                              {'/add': 7.5}, {'std_msgs/String': 'abc'})
    assert sync.digest(state) == sync.digest(again)


def remote_state(**kw):
    base = {'pubs': {'/chatter': ['/talker']}, 'subs': {'/cmd': ['/base']},
            'srvs': {}, 'types': {'/chatter': 'std_msgs/String', '/cmd': 'geometry_msgs/Twist'},
            'md5': {'std_msgs/String': '992ce8a1687cec8c8bd883ec73ca41d1'},
            'nodes': {'/talker': 'http://10.77.0.2:4001/', '/base': 'http://10.77.0.2:4002/'}}
    base.update(kw)
    return base


def test_plan_registers_remote_nodes_under_bridge_owned_names():
    result = sync.plan('cloud', remote_state(), snapshot(), set(), ALL, ALL, {}, {})
    assert result.registrations == {
        sync.Registration('pub', '/chatter', '/cloud/talker', 'http://10.77.0.2:4001/', 'std_msgs/String'),
        sync.Registration('sub', '/cmd', '/cloud/base', 'http://10.77.0.2:4002/', 'geometry_msgs/Twist')}
    assert result.problems == []


def test_plan_never_takes_the_name_of_a_local_node():
    local = snapshot(pubs={'/other': ['/cloud/talker']}, types={'/other': 'std_msgs/Int32'})
    result = sync.plan('cloud', remote_state(), local, set(), ALL, ALL, {}, {})
    assert all(r.caller_id != '/cloud/talker' for r in result.registrations)
    assert any('local node /cloud/talker' in p for p in result.problems)
    # but it re-plans its own proxy of that name
    result = sync.plan('cloud', remote_state(), local, {'/cloud/talker'}, ALL, ALL, {}, {})
    assert any(r.caller_id == '/cloud/talker' for r in result.registrations)


def test_plan_rejects_type_and_md5_conflicts():
    local = snapshot(pubs={'/chatter': ['/me']}, types={'/chatter': 'std_msgs/Int32'})
    result = sync.plan('cloud', remote_state(), local, set(), ALL, ALL, {}, {})
    assert not any(r.name == '/chatter' for r in result.registrations)
    assert any('type std_msgs/String there, std_msgs/Int32 here' in p for p in result.problems)
    result = sync.plan('cloud', remote_state(), snapshot(), set(), ALL, ALL, {}, {'std_msgs/String': 'ffff'})
    assert not any(r.name == '/chatter' for r in result.registrations)
    assert any('md5' in p for p in result.problems)


def test_plan_applies_the_filters_on_import_too():
    result = sync.plan('cloud', remote_state(), snapshot(), set(), sync.Filter(['/cmd']), ALL, {}, {})
    assert {r.name for r in result.registrations} == {'/cmd'}


def test_services_newest_provider_wins_both_ways():
    state = remote_state(srvs={'/echo': ['/monitor', 'rosrpc://10.77.0.2:5000', 1.0]},
                         nodes={'/monitor': 'http://10.77.0.2:4003/'})
    local = snapshot(services={'/echo': '/old_monitor'}, service_apis={'/echo': 'rosrpc://10.77.0.1:5000'})
    # the local provider has been there for 30 s, the remote one for 1 s: the remote one takes over
    taken = sync.plan('cloud', state, local, set(), ALL, ALL, {'/echo': 30.0}, {})
    assert sync.Registration('srv', '/echo', '/cloud/monitor', 'http://10.77.0.2:4003/',
                             'rosrpc://10.77.0.2:5000') in taken.registrations
    # a local provider started after the remote one keeps the service
    kept = sync.plan('cloud', state, local, set(), ALL, ALL, {'/echo': 0.2}, {})
    assert not any(r.kind == 'srv' for r in kept.registrations)
    # when the master already points at our own proxy, the remote provider stays registered
    proxied = snapshot(services={'/echo': '/cloud/monitor'}, service_apis={'/echo': 'rosrpc://10.77.0.2:5000'})
    assert any(r.kind == 'srv' for r in sync.plan('cloud', state, proxied, {'/cloud/monitor'}, ALL, ALL,
                                                   {'/echo': 0.0}, {}).registrations)


def test_uri_spelling_alternates_per_generation():
    assert sync.uri_spelling('http://h:1/', 0) == 'http://h:1/'
    assert sync.uri_spelling('http://h:1/', 1) == 'http://h:1'
    assert sync.uri_spelling('http://h:1/', 2) == 'http://h:1/'
    assert sync.uri_spelling('http://h:1', 1) == 'http://h:1/'


def test_a_node_the_master_still_holds_keeps_its_spelling():
    """rosmaster keeps a node while any registration lists it (a proxy's service a local provider took over):
    the other spelling would make it shut down the URI it holds, which is the remote node itself."""
    wanted = {'/robot/move_base': 'http://10.77.0.1:45105', '/robot/mfg': 'http://10.77.0.1:40049',
              '/robot/new': 'http://10.77.0.1:5000/'}
    known = {'/robot/move_base': 'http://10.77.0.1:45105/',     # held under the other spelling
             '/robot/mfg': 'http://10.77.0.1:40049',            # held as we would register it
             '/robot/old': 'http://10.77.0.1:1/',               # not ours to register
             '/robot/new': 'http://10.77.0.1:6000/'}            # another process of that name: not the same node
    kept = sync.kept_spellings(wanted, known)
    assert kept == {'/robot/move_base': 'http://10.77.0.1:45105/'}
    a = sync.Registration('pub', '/t', '/robot/move_base', 'http://10.77.0.1:45105', 'std_msgs/String')
    b = sync.Registration('sub', '/u', '/robot/mfg', 'http://10.77.0.1:40049', 'std_msgs/String')
    assert sync.respell({a, b}, kept) == {a._replace(caller_api='http://10.77.0.1:45105/'), b}


def test_a_remote_node_started_again_at_a_new_uri_is_registered_there_at_once():
    """A cloud module failed over and started again as a standby: same name, new port. A spelling kept for the
    old process must not hold its proxy at the dead URI, and the new URI waits for nothing (the master may hold the
    old process for ever, through a service of it that a local provider took over)."""
    kept = {'/cloud/global_goal_manager': 'http://10.77.0.2:38921/'}
    new = sync.Registration('pub', '/global_goal', '/cloud/global_goal_manager', 'http://10.77.0.2:39863',
                            'geometry_msgs/PoseStamped')
    assert sync.respell({new}, kept) == {new}
    assert not sync.must_wait('http://10.77.0.2:38921/', 'http://10.77.0.2:39863')
    assert not sync.must_wait(None, 'http://10.77.0.2:39863')
    assert not sync.must_wait('http://10.77.0.2:39863', 'http://10.77.0.2:39863')
    assert sync.must_wait('http://10.77.0.2:39863/', 'http://10.77.0.2:39863')      # a change of spelling waits


def test_diff_and_identity_conflicts():
    a = sync.Registration('pub', '/t', '/cloud/n', 'http://h:1/', 'std_msgs/String')
    b = sync.Registration('pub', '/t', '/cloud/n', 'http://h:1', 'std_msgs/String')
    unregister, register = sync.diff({a}, {b})
    assert unregister == [a] and register == [b]
    assert sync.conflicting_identities([b], [a]) == {'/cloud/n'}
    assert sync.conflicting_identities([b], []) == set()


def test_a_forced_reconnect_respells_a_node_in_one_batch_where_the_master_holds_nothing_else_of_it():
    """A peer that lost us and hears us again: its nodes are registered at the other spelling. Where the batch
    removes every registration the master holds of a node, it is registered again in the same batch, right after
    its own removals; a node the master holds beyond them waits for a poll (rosmaster would shut it down)."""
    old, new = 'http://10.77.0.2:4000/', 'http://10.77.0.2:4000'
    pub = sync.Registration('pub', '/goal', '/cloud/mfg', old, 'geometry_msgs/PoseStamped')
    sub = sync.Registration('sub', '/pose', '/cloud/mfg', old, 'geometry_msgs/PoseStamped')
    srv = sync.Registration('srv', '/reset', '/cloud/ggm', 'http://10.77.0.2:5000/', 'rosrpc://10.77.0.2:5001')
    ggm = sync.Registration('pub', '/global_goal', '/cloud/ggm', 'http://10.77.0.2:5000/', 'std_msgs/String')
    snap = snapshot(pubs={'/goal': {'/cloud/mfg', '/local'}, '/global_goal': {'/cloud/ggm'}},
                    subs={'/pose': {'/cloud/mfg'}}, services={'/reset': '/cloud/ggm'},
                    nodes={'/cloud/mfg': old, '/cloud/ggm': 'http://10.77.0.2:5000/', '/local': 'http://l:1/'})
    unregister = [pub, sub, srv, ggm]
    register = [r._replace(caller_api=r.caller_api.rstrip('/')) for r in unregister]
    assert sync.respell_in_place(unregister, register, [], snap, {}) == {'/cloud/mfg', '/cloud/ggm'}
    # the master lists a registration of mfg that the batch does not remove: it waits
    assert sync.respell_in_place([pub], [register[0]], [], snap, {}) == set()
    # the bridge keeps one of its registrations at the old spelling: it waits
    assert sync.respell_in_place([pub], [register[0]], [sub], snap, {}) == set()
    # a service of ggm that a local provider took over: the master holds ggm without listing it
    assert sync.respell_in_place(unregister, register, [], snap,
                                 {'/cloud/ggm': 'http://10.77.0.2:5000/'}) == {'/cloud/mfg'}
    # not a change of spelling (a node new to the master, or started again at another port): not in place
    moved = [r._replace(caller_api='http://10.77.0.2:4100') for r in register[:2]]
    assert sync.respell_in_place(unregister[:2], moved, [], snap, {}) == set()
    calls = sync.batch_order([pub, sub, srv, ggm], register, {'/cloud/mfg'})
    assert calls == [(False, srv), (False, ggm), (False, sub), (False, pub), (True, register[0]),
                     (True, register[1]), (True, register[2]), (True, register[3])]


def test_protocol_authenticates_and_rejects_replays():
    msg = {'from': 'robot', 'session': 's1', 'seq': 1, 'kind': 'hb', 't1': 1.5}
    data = protocol.encode(b'secret-one', msg)
    assert protocol.decode(b'secret-one', data) == msg
    with pytest.raises(protocol.ProtocolError, match='HMAC'):
        protocol.decode(b'secret-two', data)
    with pytest.raises(protocol.ProtocolError):
        protocol.decode(b'secret-one', b'garbage')
    tampered = data[:-1] + bytes([data[-1] ^ 1])
    with pytest.raises(protocol.ProtocolError):
        protocol.decode(b'secret-one', tampered)
    guard = protocol.ReplayGuard()
    assert guard.accept(msg) and not guard.accept(msg)
    assert guard.accept(dict(msg, seq=2)) and guard.accept(dict(msg, session='s2', seq=1))


def test_link_estimator_rtt_offset_and_loss():
    est = LinkEstimator(rate=10.0, loss_timeout=1.5)
    # peer clock is 5 s ahead; one-way delay 20 ms each way; the peer holds the heartbeat 3 ms
    for i in range(20):
        t1 = 100.0 + i * 0.1
        t2 = t1 + 0.020 + 5.0
        t3 = t2 + 0.003
        t4 = t3 - 5.0 + 0.020
        est.on_heartbeat(t4, t1, t2, t3)
    q = est.quality(t4)
    assert q.rtt == pytest.approx(0.040, abs=1e-9)
    assert q.clock_offset == pytest.approx(5.0, abs=1e-9)
    assert q.alive and q.loss < 0.1
    assert not est.alive(t4 + 1.6)
    # half of the heartbeats lost
    est2 = LinkEstimator(rate=10.0, loss_timeout=1.5)
    for i in range(0, 100, 2):
        est2.on_heartbeat(i * 0.1)
    assert est2.quality(9.9).loss == pytest.approx(0.5, abs=0.05)
    assert math.isnan(est2.quality(9.9).rtt)


def section(**kw):
    from cnr_params import load_yaml
    base = load_yaml(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config', 'bridge.yaml'))
    base.update(name='robot', listen='10.77.0.1:11511', peers=[dict(name='cloud', address='10.77.0.2:11511')],
                secret='0123456789', allow_topics=['/tf'])
    base.update(kw)
    return Section({k: v for k, v in base.items() if v is not None}, '/bridge')


def test_config_parses_and_rejects_bad_values(tmp_path):
    cfg = config.parse(section())
    assert cfg.listen == ('10.77.0.1', 11511) and cfg.peers[0].name == 'cloud'
    assert cfg.topics.passes('/tf') and not cfg.services.passes('/anything')
    secret = tmp_path / 'secret'
    secret.write_text('file-secret-123\n')
    assert config.parse(section(secret=None, secret_file=str(secret))).secret == b'file-secret-123'
    for kw, field in ((dict(secret=None), 'secret'), (dict(secret='short'), 'secret'),
                      (dict(peers=[]), 'peers'), (dict(listen='nowhere'), 'listen'),
                      (dict(peers=[dict(name='cloud', address='h:99999')]), 'address'),
                      (dict(peers=[dict(name='robot', address='h:1')]), 'name'),
                      (dict(secret=None, secret_file=str(tmp_path / 'missing')), 'secret_file'),
                      (dict(loss_timeout=0.1), 'loss_timeout'), (dict(allow_topics=[3]), 'allow_topics'),
                      (dict(heartbeat_rate=None), 'heartbeat_rate: missing'), (dict(nice=-21), 'nice'),
                      (dict(nice=None), 'nice: missing'),
                      (dict(deny_services=None), 'deny_services: missing')):
        with pytest.raises(ConfigError) as err:
            config.parse(section(**kw))
        assert field in str(err.value) and str(err.value).startswith('/bridge: ')


def test_filter_memo_answers_like_the_globs_and_forgets_beyond_its_limit():
    f = sync.Filter(['/move_base/*', '/tf'], ['*/set_logger_level'])
    f.MEMO_LIMIT = 3
    names = ['/move_base/goal', '/tf', '/tf_static', '/move_base/set_logger_level', '/odom'] * 2
    assert [f.passes(n) for n in names] == [True, True, False, False, False] * 2
    assert len(f._memo) <= 3


def test_a_proxy_the_master_holds_at_the_remote_nodes_uri_is_no_local_node():
    """A registration of ``/cloud/talker`` at the remote node's own URI (either spelling) that the bridge no longer
    counts as its own (a plan on a snapshot older than its last changes) is its proxy, imported again: only a node
    elsewhere is a local node of that name."""
    for held in ('http://10.77.0.2:4001/', 'http://10.77.0.2:4001'):
        local = snapshot(pubs={'/chatter': ['/cloud/talker']}, types={'/chatter': 'std_msgs/String'},
                         nodes={'/cloud/talker': held})
        result = sync.plan('cloud', remote_state(), local, set(), ALL, ALL, {}, {})
        assert any(r.caller_id == '/cloud/talker' for r in result.registrations), held
        assert result.problems == []
    assert sync.same_node('http://h:1/', 'http://h:1') and not sync.same_node('http://h:1/', 'http://h:2/')
    assert sync.is_proxy('/cloud/talker', ['cloud']) and not sync.is_proxy('/cloudy', ['cloud'])


def test_a_hidden_local_provider_keeps_its_age_until_it_serves_again():
    """The robot's provider (first seen at 0) is hidden by the cloud's newer one (10) from 12 on; the cloud is lost at
    30 and the robot's serves again: it is 30 s old, not new, so the cloud's (20 s old) wins again when it returns."""
    robot, cloud = ('/flap_robot', 'rosrpc://r:1'), ('/cloud/flap_cloud', 'rosrpc://c:1')
    seen, ages = sync.service_ages({}, {'/s': robot}, {}, 0.0)
    assert ages == {'/s': 0.0}
    seen, ages = sync.service_ages(seen, {'/s': cloud}, {'/s': robot}, 12.0)
    seen, ages = sync.service_ages(seen, {'/s': cloud}, {'/s': robot}, 20.0)
    seen, ages = sync.service_ages(seen, {'/s': robot}, {}, 30.0)
    assert ages == {'/s': 30.0}
    state = remote_state(srvs={'/s': ['/flap_cloud', 'rosrpc://c:1', 20.0]},
                         nodes=dict(remote_state()['nodes'], **{'/flap_cloud': 'http://10.77.0.2:4003/'}))
    local = snapshot(services={'/s': '/flap_robot'}, service_apis={'/s': 'rosrpc://r:1'})
    result = sync.plan('cloud', state, local, set(), ALL, ALL, ages, {})
    assert any(r.kind == 'srv' and r.caller_id == '/cloud/flap_cloud' for r in result.registrations)
    # a provider gone from the master and not hidden is forgotten: if it comes back, it is new
    seen, ages = sync.service_ages(seen, {}, {}, 31.0)
    assert seen == {}


def clock_state() -> dict:
    """A robot whose simulator publishes /clock and /odom and whose driver publishes /temperature."""
    return {'pubs': {'/clock': ['/sim'], '/odom': ['/sim'], '/temperature': ['/driver']}, 'subs': {}, 'srvs': {},
            'types': {'/clock': 'rosgraph_msgs/Clock', '/odom': 'nav_msgs/Odometry',
                      '/temperature': 'sensor_msgs/Temperature'}, 'md5': {},
            'nodes': {'/sim': 'http://10.77.0.1:4001/', '/driver': 'http://10.77.0.1:4002/'}}


def test_a_publisher_of_an_in_order_topic_keeps_its_uri_spelling_in_every_generation():
    """A forced reconnect (another spelling) gives a subscriber a second connection while the first still holds
    the outage's backlog: /clock would step back when TCP delivers it. The simulator keeps its spelling for all its
    topics (a node has one URI in a master); the driver is reconnected as before."""
    apis = []
    for generation in range(4):
        result = sync.plan('robot', clock_state(), sync.Snapshot(), set(), ALL, ALL, {}, {}, generation,
                           sync.Filter(['/clock']))
        apis.append({r.caller_id: r.caller_api for r in result.registrations})
    assert [a['/robot/sim'] for a in apis] == ['http://10.77.0.1:4001/'] * 4
    assert [a['/robot/driver'] for a in apis] == ['http://10.77.0.1:4002/', 'http://10.77.0.1:4002'] * 2
    assert sync.in_order_publishers(clock_state(), sync.Filter(['/clock'])) == {'/sim'}
    # without in-order topics every node alternates, the simulator too
    plain = sync.plan('robot', clock_state(), sync.Snapshot(), set(), ALL, ALL, {}, {}, 1, sync.Filter())
    assert {r.caller_api for r in plain.registrations if r.caller_id == '/robot/sim'} == {'http://10.77.0.1:4001'}


def test_a_peer_that_lost_us_alone_has_its_nodes_reconnected_here_once():
    """An outage in one direction: only the peer lost us, but our connections to its nodes stalled as well."""
    from multimaster_bridge.core.sync import rejoined_without_our_loss as rejoined
    assert rejoined(False, True, since_our_return=30.0, loss_timeout=1.5)          # it lost us, we heard it
    assert not rejoined(True, True, 30.0, 1.5) and not rejoined(False, False, 30.0, 1.5)
    assert not rejoined(None, True, 30.0, 1.5)                                      # its first heartbeat
    # both lost each other: our own loss already gave a new generation; a second one would undo it
    assert not rejoined(False, True, since_our_return=0.2, loss_timeout=1.5)


def test_in_order_topics_is_a_required_list_of_globs():
    from cnr_params import load_yaml
    here = os.path.dirname(os.path.abspath(__file__))
    base = load_yaml(os.path.join(here, '..', 'config', 'bridge.yaml'))
    base.update(name='robot', listen='10.77.0.1:11511', peers=[dict(name='cloud', address='10.77.0.2:11511')],
                secret='0123456789')
    assert config.parse(Section(base, '/bridge')).in_order.passes('/clock')
    for value, message in ((None, 'in_order_topics: missing'), ([3], 'in_order_topics')):
        data = dict(base, in_order_topics=value) if value is not None else \
            {k: v for k, v in base.items() if k != 'in_order_topics'}
        with pytest.raises(ConfigError, match=message):
            config.parse(Section(data, '/bridge'))


def test_a_restore_is_timed_to_the_poll_from_which_the_invariant_held_until_the_next_outage():
    from multimaster_bridge.watch import bridge_filters, restore_times
    bad, ok = ['missing'], []
    samples = [(10.0, bad), (10.1, ok), (10.2, bad), (10.3, ok), (10.4, ok),      # back at 10.0: held from 10.3 on
               (11.0, bad), (12.0, ok),                                            # outage 2, back at 11.5
               (13.0, bad), (13.5, bad)]                                           # outage 3, back at 13.2: never
    r = restore_times(samples, began=[9.0, 10.9, 12.9], ended=[10.0, 11.5, 13.2])
    assert [None if x is None else round(x, 3) for x in r.restores] == [0.3, 0.5, None]
    assert r.unrestored == 1 and r.max == 0.5 and r.median == pytest.approx(0.4) and r.last_problems[2] == bad
    name, filters = bridge_filters([{'name': '/robot', 'allow_topics': ['/a/*'], 'deny_topics': ['/a/x']},
                                    {'allow_services': '/s'}])
    assert name == 'robot' and filters.passes('pub', '/a/b') and not filters.passes('sub', '/a/x')
    assert filters.passes('srv', '/s') and not filters.passes('srv', '/a/b')
    with pytest.raises(ValueError, match='name: missing'):
        bridge_filters({'allow_topics': ['*']})


def test_a_kept_state_ages_with_the_time_since_it_arrived():
    """The peer's provider was 2 s old when its state was sent and the local one is 5 s old now: 4 s after the
    state arrived the peer's is 6 s old, older than the local one, which therefore serves (newest wins)."""
    state = remote_state(srvs={'/s': ['/p', 'rosrpc://c:1', 2.0]},
                         nodes=dict(remote_state()['nodes'], **{'/p': 'http://10.77.0.2:4003/'}))
    local = snapshot(services={'/s': '/mine'}, service_apis={'/s': 'rosrpc://r:1'})

    def remote_serves(st):
        return any(r.kind == 'srv' for r in sync.plan('cloud', st, local, set(), ALL, ALL, {'/s': 5.0}, {}).registrations)
    assert remote_serves(state)                               # as sent: the peer's is newer
    assert not remote_serves(sync.aged_state(state, 4.0))     # as it is now: the local one is newer
    assert sync.aged_state(state, 4.0)['srvs'] == {'/s': ['/p', 'rosrpc://c:1', 6.0]}
    assert state['srvs']['/s'][2] == 2.0 and sync.aged_state(state, 0.0) is state


def test_the_watch_keeps_every_change_of_the_violations():
    from multimaster_bridge.watch import changes
    samples = [(1.0, ['a']), (1.1, ['a']), (1.2, []), (1.3, []), (1.4, ['b']), (1.5, [])]
    # each change with the poll before it: when the state before was last seen
    assert changes(samples) == [(1.0, ['a']), (1.1, ['a']), (1.2, []), (1.3, []), (1.4, ['b']), (1.5, [])]
    assert changes([(1.0, []), (1.1, []), (1.2, []), (1.3, ['a'])]) == [(1.0, []), (1.2, []), (1.3, ['a'])]
    assert changes([]) == []


def test_a_service_proxy_the_master_no_longer_lists_counts_as_not_registered():
    proxy = sync.Registration('srv', '/move_base/set_parameters', '/cloud/move_base', 'http://c:1/', 'rosrpc://c:2')
    kept = sync.Registration('srv', '/move_base/make_plan', '/cloud/move_base', 'http://c:1/', 'rosrpc://c:3')
    topic = sync.Registration('pub', '/odom', '/cloud/move_base', 'http://c:1/', 'nav_msgs/Odometry')
    owned = {'/cloud/move_base'}
    # a standby opened the service over the proxy and closed it again: no provider at all
    snap = sync.Snapshot(services={'/move_base/make_plan': '/cloud/move_base'},
                         nodes={'/cloud/move_base': 'http://c:1/'})
    gone, taken = sync.displaced({proxy, kept, topic}, snap, owned)
    assert gone == {proxy} and taken == {}
    # a local node registered it after the proxy: it is listed, and it is the newest provider
    snap.services['/move_base/set_parameters'] = '/move_base'
    snap.nodes['/move_base'] = 'http://r:5/'
    gone, taken = sync.displaced({proxy, kept, topic}, snap, owned)
    assert gone == {proxy} and taken == {'/move_base/set_parameters': '/move_base'}
    # listed as registered: nothing displaced
    snap.services['/move_base/set_parameters'] = '/cloud/move_base'
    assert sync.displaced({proxy, kept, topic}, snap, owned) == (set(), {})


def test_each_discrepancy_is_timed_from_the_return_or_from_when_it_arose():
    """Back at 10.0: ``a`` (there at the return) goes at 10.3; ``b`` arises after 10.95 (the peer registered
    something new after the return) and goes at 11.4; ``c`` arises after 11.95 and goes at 12.1. The invariant held
    without a break only from 12.1 on (2.1 s), but no discrepancy lasted longer than 0.45 s."""
    from multimaster_bridge.core.restore import changes, discrepancy_restore, unbroken_restore
    from multimaster_bridge.watch import restore_times
    samples = [(9.5, ['a']), (10.05, ['a']), (10.3, []), (10.95, []), (11.0, ['b']), (11.2, ['b']), (11.4, []),
               (11.95, []), (12.0, ['c']), (12.1, [])]
    r = restore_times(samples, began=[9.0], ended=[10.0])
    # b: last seen absent at 10.95, gone at 11.4: 0.45 s
    assert r.restores[0] == pytest.approx(2.1) and r.lags[0] == pytest.approx(0.45)
    # what watch.tsv keeps (the changes, each with the poll before it) times them as every poll does
    record = changes(samples)
    assert discrepancy_restore(record, 10.0) == (pytest.approx(0.45), 0.0)
    assert unbroken_restore(record, 10.0) == pytest.approx(2.1)
    # a record of the changes alone (older watch.tsv files): from the change before, an overestimate
    alone = [(t, w) for i, (t, w) in enumerate(samples) if i == 0 or w != samples[i - 1][1]]
    assert discrepancy_restore(alone, 10.0) == (pytest.approx(1.1), 0.0)      # b: from 10.3 to 11.4
    assert discrepancy_restore(alone, 10.0, window_end=12.05) == (None, pytest.approx(0.65))   # c: from 11.4
    # none after the return: 0 (the watch then reports its first poll after the return)
    assert discrepancy_restore([(9.5, []), (11.0, [])], 10.0) == (0.0, 0.0)
    assert restore_times([(9.5, []), (10.05, []), (10.1, [])], [9.0], [10.0]).lags == [pytest.approx(0.05)]
    # still there when the next outage begins: open, with its age then
    lag, open_age = discrepancy_restore(record, 10.0, window_end=12.05)
    assert lag is None and open_age == pytest.approx(0.1)                      # c: from the poll at 11.95
    assert discrepancy_restore(samples, 10.0, window_end=12.05) == (None, pytest.approx(0.1))   # from 11.95
    assert unbroken_restore(record, 10.0, window_end=12.05) is None
    assert discrepancy_restore([(9.5, ['a'])], 10.0, window_end=13.0) == (None, 3.0)
