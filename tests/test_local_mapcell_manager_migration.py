"""local_mapcell_manager moved between two managed instances on one real master, driven through the real lease
protocol by one grantor (tests/migration_driver.py): instance A (``local_mapcell_manager@robot``) stores a
stream of merged measurements, instance B (started as ``/local_mapcell_manager_b`` with host ``cloud``) is a
standby; A is frozen and B promoted with A's state while the stream goes on. B must end with every
measurement exactly once, in order (its service and its store file), including the ones published between the
freeze and the promotion; A publishes nothing after its freeze, B nothing before its promotion (told apart by
the ``cnr_instance`` connection header of ``mapcell_measurements``). A second test: a lapsed lease holds the
output back, the stored measurements are published when the lease is granted again."""
import os
import threading
import time

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

MODULE = 'local_mapcell_manager'
A, B = f'{MODULE}@robot', f'{MODULE}@cloud'


def node_params(workspace, store, host):
    """What modules.launch loads into the node's namespace (managed: migration_role:=standby)."""
    from cnr_params import load_yaml
    from migration_driver import managed_params
    p = dict(load_yaml(os.path.join(workspace, 'config', 'local_mapcell_manager.yaml')))
    p.update(load_yaml(os.path.join(workspace, 'config', 'scenarios', 'corridor.yaml')))
    p.update(store=str(store), map_file=os.path.join(workspace, 'maps', 'corridor.yaml'),
             migration=managed_params(workspace, host))
    return p


def key(stamp, x, y, temperature):
    """A measurement at the store's precision."""
    return round(stamp, 6), round(x, 4), round(y, 4), round(temperature, 4)


def msg_key(m):
    return key(m.header.stamp.to_sec(), m.x, m.y, m.temperature)


class Stream:
    """The test's merger: publishes numbered merged measurements on /merged_measurements, in the corridor's
    cells; records what it published and what arrives on /mapcell_measurements (with the publishing instance
    and the arrival time)."""

    def __init__(self):
        from cnr_msgs.msg import MergedMeasurement
        self.pub = rospy.Publisher('/merged_measurements', MergedMeasurement, queue_size=1000)
        self.sent = []
        self.received = []                  # (instance, key, arrival: monotonic s)
        self.lock = threading.Lock()
        self.sub = rospy.Subscriber('/mapcell_measurements', MergedMeasurement, self._on_stored, queue_size=1000)
        self.running = False
        self.thread = None

    def _on_stored(self, m):
        with self.lock:
            self.received.append((m._connection_header.get('cnr_instance'), msg_key(m), time.monotonic()))

    def send(self, n=1):
        from cnr_msgs.msg import MergedMeasurement
        for _ in range(n):
            i = len(self.sent) + 1
            m = MergedMeasurement(x=0.5 + (i % 11), y=0.5 if (i // 11) % 2 else -0.5, yaw=0.01 * i,
                                  temperature=22.0 + 0.001 * i, stamp_difference=0.01, cell=-1)
            m.header.stamp = rospy.Time.from_sec(1000.0 + 0.05 * i)
            m.pose_stamp = rospy.Time.from_sec(1000.0 + 0.05 * i - 0.01)
            m.header.frame_id = 'map'
            self.pub.publish(m)
            self.sent.append(msg_key(m))

    def start(self, rate=40.0):
        """Publish continuously (paced at ``rate`` Hz) until stop()."""
        self.running = True

        def loop():
            while self.running:
                self.send()
                time.sleep(1.0 / rate)
        self.thread = threading.Thread(target=loop, daemon=True)
        self.thread.start()

    def stop(self):
        self.running = False
        self.thread.join(5)

    def wait_sent(self, n, timeout=30):
        wait_until(lambda: len(self.sent) >= n, timeout, f'{n} measurements published')

    def by(self, instance):
        with self.lock:
            return [(k, t) for i, k, t in self.received if i == instance]

    def close(self):
        self.sub.unregister()
        self.pub.unregister()


def served(ros, node):
    """The node's own services (not its control service nor rospy's logger services)."""
    ours = {f'{node}/get_cell', f'{node}/get_cell_states', f'{node}/get_measurements'}
    return [name for name, providers in ros.master.call('getSystemState')[2] if name in ours and node in providers]


def publishers_of(ros, topic):
    return [p for name, providers in ros.master.call('getSystemState')[0] if name == topic for p in providers]


def get_measurements(node, timeout=2.0):
    from cnr_msgs.srv import GetMeasurements
    rospy.wait_for_service(f'/{node}/get_measurements', timeout)
    return rospy.ServiceProxy(f'/{node}/get_measurements', GetMeasurements)(-1)


def stored(node, n):
    """The node's stored measurements once there are at least n (None before, or while it does not serve)."""
    try:
        res = get_measurements(node, 0.5)
    except (rospy.ROSException, rospy.ServiceException):
        return None
    return res if res.success and len(res.measurements) >= n else None


@pytest.fixture
def lmm(ros, workspace, tmp_path):
    """Starts managed instances on demand: start('robot') is /local_mapcell_manager, start('cloud')
    /local_mapcell_manager_b; one LeaseDriver for both."""
    from migration_driver import LeaseDriver, instance_names, instance_starter
    driver = LeaseDriver(MODULE, hosts=('robot', 'cloud'))
    stream = Stream()
    start, procs = instance_starter(ros.master, driver, MODULE,
                                    lambda host: node_params(workspace, tmp_path / f'{host}.tsv', host), 'lmm')
    yield start, driver, stream, tmp_path
    for proc in procs.values():
        ros.master.stop_child(proc)
    stream.close()
    driver.close()
    for host in procs:
        ros.master.call('deleteParam', f'/{instance_names(MODULE)[host]}')


class Replicas:
    """The test's copy of the active instance's replica stream (as the manager keeps it)."""

    def __init__(self):
        import threading
        from cnr_msgs.msg import ModuleState
        from migration_manager.core import state as codec
        self.lock = threading.Lock()
        self.replica = codec.Replica(MODULE)
        self.messages = []
        self.sub = rospy.Subscriber(f'/migration/{MODULE}/state', ModuleState, self._on, queue_size=20)

    def _on(self, msg):
        with self.lock:
            self.messages.append((msg.instance, msg.seq, msg.base_seq, len(msg.data)))
            self.replica.take(msg.instance, msg.seq, msg.base_seq, bytes(msg.data))

    def seq_of(self, instance):
        with self.lock:
            return self.replica.seq_of(instance)

    def resolve(self, instance, data):
        with self.lock:
            return self.replica.resolve(instance, data)


def test_hand_over_between_two_instances_stores_every_measurement_exactly_once(lmm, ros):
    """... with the final state as a patch: A replicates (a whole state when asked, patches between), B (a
    standby) keeps the replicas, A's freeze answers with a patch to the newest one, and B resolves it."""
    from cnr_maps.measurements import read_tsv
    from cnr_msgs.srv import InstanceControl
    from migration_manager.core import state as codec
    from migration_manager.core.lease import instance_id
    start, driver, stream, tmp = lmm
    a_id = instance_id(MODULE, 'robot')
    replicas = Replicas()

    # A: a standby buffers (stores, publishes and serves nothing), then is promoted without a state
    proc_a = start('robot')
    wait_until(lambda: stream.pub.get_num_connections() == 1, 10, 'A subscribed to merged_measurements')
    wait_until(lambda: stream.sub.get_num_connections() == 1, 10, 'subscribed to A\'s mapcell_measurements')
    assert not served(ros, f'/{MODULE}')                         # a standby serves nothing
    stream.send(5)
    driver.promote(host='robot')
    driver.wait_active(10, host='robot')
    assert len(wait_until(lambda: stored(MODULE, 5), 10, 'the buffered 5 stored by A').measurements) == 5
    stream.send(15)
    assert len(wait_until(lambda: stored(MODULE, 20), 10, '20 stored by A').measurements) == 20

    # B: a standby on the other host, while the stream goes on
    proc_b = start('cloud')
    wait_until(lambda: stream.pub.get_num_connections() == 2, 10, 'B subscribed to merged_measurements')
    wait_until(lambda: stream.sub.get_num_connections() == 2, 10, 'subscribed to both mapcell_measurements')
    assert not served(ros, f'/{MODULE}_b')
    control_b = rospy.ServiceProxy(f'/migration/{MODULE}/cloud/control', InstanceControl)
    stream.start()
    stream.wait_sent(40)

    # a whole replica (as the manager asks for one when it holds none; B, a standby, asks A too), then at
    # least one patch to it, every replica_period_authority (A is on the robot)
    wait_until(lambda: f'/{MODULE}_b' in [n for t, ns in ros.master.call('getSystemState')[1]
                                           if t == f'/migration/{MODULE}/state' for n in ns], 10,
               "B subscribed to A's replicas")
    assert rospy.ServiceProxy(f'/migration/{MODULE}/robot/control', InstanceControl)(command='keyframe').ok
    wait_until(lambda: replicas.seq_of(a_id), 10, 'a whole replica of A')
    wait_until(lambda: [m for m in replicas.messages if m[0] == a_id and m[2]], 15, 'a patch to it')
    base = replicas.seq_of(a_id)
    stream.wait_sent(len(stream.sent) + 10)
    data = driver.freeze_data(host='robot', base_seq=base)
    frozen_at = len(stream.sent)
    assert codec.decode_any(MODULE, data)[0] == base               # a patch to the replica held
    state = replicas.resolve(a_id, data)
    appended = codec.decode_any(MODULE, data)[1]['{']['measurements']['{']['time']['+']
    assert 10 <= len(appended) < len(state['measurements']['time'])     # only what was stored since the base
    stream.wait_sent(frozen_at + 15)                               # only B receives these
    wrong = dict(state, grid=dict(state['grid'], cols=12))         # a state that does not fit is refused
    res = control_b(command='promote', term=99, state=codec.encode(MODULE, wrong))
    assert not res.ok and 'grid' in res.message, res.message
    res = control_b(command='promote', term=99, state=data, base_instance=instance_id(MODULE, 'moon'))
    assert not res.ok and res.message.startswith(codec.BASE_MISSING), res.message   # not its replica: refused
    assert read_tsv(str(tmp / 'cloud.tsv')) == [] and not served(ros, f'/{MODULE}_b')    # B stored nothing yet
    promoted_at = time.monotonic()
    promoted_after = len(stream.sent)
    driver.promote(host='cloud', data=data, base_instance=a_id)    # the patch: B holds its base
    driver.wait_active(10, host='cloud')
    stream.wait_sent(promoted_after + 30)
    stream.stop()
    sent = list(stream.sent)

    # B stored every measurement exactly once, in order: its service and its file
    res = wait_until(lambda: stored(f'{MODULE}_b', len(sent)), 15, f'B to store all {len(sent)} measurements')
    assert [msg_key(m) for m in res.measurements] == sent
    assert [m.header.seq for m in res.measurements] == list(range(1, len(sent) + 1))
    assert [key(m.time, m.x, m.y, m.temperature) for m in read_tsv(str(tmp / 'cloud.tsv'))] == sent
    assert frozen_at < promoted_after < len(sent)

    # A handed over what it had stored; its file holds exactly that; it serves nothing more
    handed = [key(*v) for v in zip(*(state['measurements'][c] for c in ('time', 'x', 'y', 'temperature')))]
    assert 20 <= len(handed) <= frozen_at and handed == sent[:len(handed)]
    assert [key(m.time, m.x, m.y, m.temperature) for m in read_tsv(str(tmp / 'robot.tsv'))] == handed
    wait_until(lambda: not served(ros, f'/{MODULE}'), 10, 'the frozen A to stop serving')
    wait_until(lambda: publishers_of(ros, '/cell_states') == [f'/{MODULE}_b'], 10,
               'only B to publish cell_states (the frozen A unregistered its latched publisher)')

    # mapcell_measurements: A up to its freeze, B after its promotion, every measurement once, in order
    wait_until(lambda: len(stream.by(A)) + len(stream.by(B)) >= len(sent), 15, 'every measurement published')
    from_a, from_b = stream.by(A), stream.by(B)
    unpublished = set(state['unpublished']['measurement'])
    assert [k for k, _ in from_a] == [k for n, k in enumerate(handed, 1) if n not in unpublished]
    assert all(t > promoted_at for _, t in from_b), 'B published before its promotion'
    assert [k for k, _ in from_a] + [k for k, _ in from_b] == sent
    assert len(stream.received) == len(sent)                    # nobody else, nothing twice

    assert proc_a.alive() and proc_b.alive()
    for proc in (proc_a, proc_b):
        assert 'Traceback' not in proc.output(), proc.output()[-3000:]
    replicas.sub.unregister()


def test_a_lapsed_lease_holds_the_output_back_and_the_service_refuses(lmm, ros):
    start, driver, stream, tmp = lmm
    proc = start('robot')
    wait_until(lambda: stream.pub.get_num_connections() >= 1, 10, 'subscribed to merged_measurements')
    driver.promote(host='robot')
    driver.wait_active(10, host='robot')
    wait_until(lambda: stream.sub.get_num_connections() == 1, 10, 'subscribed to mapcell_measurements')
    stream.send(5)
    wait_until(lambda: len(stream.by(A)) == 5, 10, '5 measurements published')

    driver.cut_off()                                             # renewals unanswered: the lease runs out
    driver.wait_role('promoted', 5, host='robot')
    stream.send(7)                                               # stored, held back
    res = get_measurements(MODULE)
    assert not res.success and 'not the active instance' in res.message
    state = wait_until(lambda: (lambda s: s if len(s['measurements']['time']) == 12 else None)(
        driver.state(host='robot')), 10, 'the 7 stored during the lapse')
    assert len(state['unpublished']['measurement']) == 7
    assert len(stream.by(A)) == 5

    with driver.lock:
        driver.answering = True                                  # renewals granted again
    driver.wait_active(10, host='robot')
    wait_until(lambda: len(stream.by(A)) == 12, 10, 'the held-back measurements published')
    assert [k for k, _ in stream.by(A)] == stream.sent
    res = get_measurements(MODULE)
    assert res.success and [msg_key(m) for m in res.measurements] == stream.sent
    assert proc.alive() and 'Traceback' not in proc.output()


def test_a_standby_names_a_replica_in_its_status_only_once_it_prepared_it(ros, workspace, tmp_path):
    """A migration here waits (timeouts.replica) until the standby's status names a replica of the source; for
    the store that must mean the replica was prepared (filed and drafted ahead), or the promotion waits for a
    prepare still running (0.4 s on the capped robot in bench_migration.sh). A replica whose draft
    cannot be written (the store's directory gone) is not named; the next one, prepared, is."""
    import shutil
    from cnr_msgs.msg import InstanceStatus, ModuleState
    from migration_driver import LeaseDriver
    from migration_manager.core import state as codec
    store_dir = tmp_path / 'store'
    store_dir.mkdir()
    ros.master.call('setParam', f'/{MODULE}', node_params(workspace, store_dir / 'robot.tsv', 'robot'))
    driver = LeaseDriver(MODULE, 'robot')
    pub = rospy.Publisher(f'/migration/{MODULE}/state', ModuleState, queue_size=5)
    proc = ros.master.run(['rosrun', MODULE, MODULE], 'lmm_prepare')
    try:
        st = driver.wait_standby(30)
        assert (st.replica_of, st.replica_seq) == ('', 0)
        whole = codec.encode(MODULE, driver.state())           # a store's state (its own, empty), as the cloud's
        wait_until(lambda: pub.get_num_connections() > 0, 10, 'the standby to follow the replicas')
        shutil.rmtree(store_dir)                                # no draft can be written next to the store now
        cloud = f'{MODULE}@cloud'
        pub.publish(ModuleState(module=MODULE, instance=cloud, term=1, seq=5, base_seq=0, data=whole))
        wait_until(lambda: 'replica not prepared' in proc.output(), 10, 'the prepare to fail')
        seen = []
        wait_until(lambda: seen.append(driver.status) or len({id(s) for s in seen}) >= 3, 10,
                   'two more statuses after the failed prepare')
        assert all(s.replica_seq == 0 for s in seen[1:]), [(s.replica_of, s.replica_seq) for s in seen]
        store_dir.mkdir()
        pub.publish(ModuleState(module=MODULE, instance=cloud, term=1, seq=6, base_seq=0, data=whole))
        st = wait_until(lambda: driver.status if driver.status.replica_seq else None, 10,
                        'a status naming the prepared replica')
        assert (st.role, st.replica_of, st.replica_seq) == (InstanceStatus.STANDBY, cloud, 6)
        assert proc.alive() and 'Traceback' not in proc.output()
    finally:
        pub.unregister()
        ros.master.stop_child(proc)
        driver.close()
        ros.master.call('deleteParam', f'/{MODULE}')


class Feed:
    """The real merger's inputs: ground-truth poses at 20 Hz and temperatures at 5 Hz (stamps from 1000 s on,
    0.05 s apart: the session's master has sim time and no clock here), along the corridor's cells; records
    every merged measurement the merger publishes."""

    def __init__(self):
        from cnr_msgs.msg import MergedMeasurement
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Temperature
        self.pose_pub = rospy.Publisher('/base_pose_ground_truth', Odometry, queue_size=100)
        self.temp_pub = rospy.Publisher('/temperature', Temperature, queue_size=100)
        self.merged = []
        self.lock = threading.Lock()
        self.sub = rospy.Subscriber('/merged_measurements', MergedMeasurement, self._on_merged, queue_size=1000)
        self.running = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _on_merged(self, m):
        with self.lock:
            self.merged.append(msg_key(m))

    def _loop(self):
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import Temperature
        i = 0
        while self.running:
            i += 1
            now = rospy.Time.from_sec(1000.0 + 0.05 * i)
            odom = Odometry()
            odom.header.stamp, odom.header.frame_id = now, 'map'
            odom.pose.pose.position.x, odom.pose.pose.position.y = 0.5 + (i * 0.05) % 10, 0.5
            odom.pose.pose.orientation.w = 1.0
            self.pose_pub.publish(odom)
            if i % 4 == 0:
                t = Temperature(temperature=22.0 + 0.01 * (i % 100))
                t.header.stamp = now - rospy.Duration(0.02)
                self.temp_pub.publish(t)
            time.sleep(0.05)

    def count(self):
        with self.lock:
            return len(self.merged)

    def close(self):
        self.running = False
        self.thread.join(5)
        for x in (self.sub, self.pose_pub, self.temp_pub):
            x.unregister()


def test_a_failover_recovers_from_the_merger_what_no_instance_received(lmm, ros, workspace):
    """A (active) is lost without a freeze; the merger goes on publishing while no store receives; B, started
    late, is promoted with A's last replicated state and asks the real merger (``~recent``) for what came
    after it: B's store holds every merged measurement once, in order."""
    from cnr_params import load_yaml
    start, driver, _stream, tmp = lmm
    ros.master.call('setParam', '/merger', dict(load_yaml(os.path.join(workspace, 'config', 'merger.yaml'))))
    merger = ros.master.run(['rosrun', 'merger', 'merger'], 'merger')
    feed = Feed()
    try:
        # The feed hears the merger before A subscribes, so no store can hold a measurement the feed missed.
        wait_until(lambda: feed.count() >= 1, 30, 'the merger to publish')
        proc_a = start('robot')
        driver.promote(host='robot')
        driver.wait_active(10, host='robot')
        wait_until(lambda: feed.count() >= 5, 30, 'the merger to publish')
        stored_a = wait_until(lambda: stored(MODULE, 5), 10, 'A to store').measurements
        replicated = driver.state(host='robot')                   # the newest state the manager holds
        ros.master.stop_child(proc_a)                             # A is lost (its host cut off): no freeze
        lost_from = len(replicated['measurements']['time'])
        published_at_loss = feed.count()
        wait_until(lambda: feed.count() >= published_at_loss + 8, 30, 'measurements no store receives')
        proc_b = start('cloud')                                   # B subscribes only now
        wait_until(lambda: driver.grantor.may_promote(time.monotonic()), 10, 'A\'s lease to run out')
        driver.promote(replicated, host='cloud')
        driver.wait_active(10, host='cloud')
        n = feed.count() + 5
        wait_until(lambda: feed.count() >= n, 30, 'more measurements after the promotion')
        feed.running = False
        feed.thread.join(5)
        with feed.lock:
            merged = list(feed.merged)
        res = wait_until(lambda: stored(f'{MODULE}_b', len(merged)), 15, f'B to store all {len(merged)}')
        keys = [msg_key(m) for m in res.measurements]
        # The merger may have published before the feed's connection was up: A, promoted without a state, recovers
        # those from the merger's retention too, so B's store may begin with a few the feed never heard
        assert merged[0] in keys, f'B misses the first measurement the feed heard: {merged[0]}'
        early = keys.index(merged[0])
        assert keys[early:] == merged and len(set(keys)) == len(keys)
        assert early <= 5 and [k[0] for k in keys[:early + 1]] == sorted(k[0] for k in keys[:early + 1])
        assert len(merged) > published_at_loss + 8 > lost_from >= len(stored_a) >= 5
        assert 'recovered' in proc_b.output() and 'Traceback' not in proc_b.output(), proc_b.output()[-3000:]
    finally:
        feed.close()
        ros.master.stop_child(merger)
        ros.master.call('deleteParam', '/merger')
