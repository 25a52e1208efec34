"""The store's input through the store-and-forward relay on one real master, with real nodes: the robot's
cnr_store_forward sender and two managed local_mapcell_manager instances driven through the real lease protocol
(tests/migration_driver.py). The active instance A is killed (SIGKILL: no freeze, no final state) in the middle
of a stream of merged measurements, after it stored and acknowledged more than its last replicated state holds;
the stream goes on while no store runs; B, started only then, is promoted with that replicated state. No merger
retains anything here: B's store must end with every measurement exactly once, in order, because B acknowledges
from the mark its state holds and the sender sends everything after it again."""
import os
import signal
import time

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

from test_local_mapcell_manager_migration import MODULE, Stream, node_params, stored  # noqa: E402

STREAM = 'merged_measurements'


def relay_params(workspace, store, host):
    """What modules.launch loads for a store with ``relay_stream:=merged_measurements``."""
    from cnr_params import load_yaml
    p = node_params(workspace, store, host)
    p.update(relay_stream=STREAM, relay=load_yaml(os.path.join(workspace, 'config', 'store_forward.yaml')))
    return p


def sender_params(workspace, queue_dir):
    from cnr_params import load_yaml
    p = dict(load_yaml(os.path.join(workspace, 'config', 'store_forward.yaml')), stream=STREAM)
    p['sender'] = dict(p['sender'], input_topic='/merged_measurements', queue_dir=str(queue_dir))
    return p


def stored_keys(node, n):
    """The node's stored measurements (keys) once it holds n, or what it holds after 30 s."""
    from cnr_harness import WaitTimeout
    from test_local_mapcell_manager_migration import get_measurements, msg_key
    try:
        res = wait_until(lambda: stored(node, n), 30, f'{node} to store all {n} measurements')
    except WaitTimeout:
        res = get_measurements(node)
    return [msg_key(m) for m in res.measurements]


@pytest.fixture
def relay(ros, workspace, tmp_path):
    from migration_driver import LeaseDriver, instance_names, instance_starter
    driver = LeaseDriver(MODULE, hosts=('robot', 'cloud'))
    stream = Stream()
    ros.master.call('setParam', '/store_forward_sender', sender_params(workspace, tmp_path / 'queue'))
    sender = ros.master.run(['rosrun', 'cnr_store_forward', 'sender'], 'relay_sender')
    wait_until(lambda: stream.pub.get_num_connections() >= 1, 30, 'the sender subscribed to merged_measurements')
    start, procs = instance_starter(ros.master, driver, MODULE,
                                    lambda host: relay_params(workspace, tmp_path / f'{host}.tsv', host), 'lmm_relay')
    yield start, driver, stream, sender, tmp_path
    for proc in procs.values():
        if proc.alive():
            ros.master.stop_child(proc)
    ros.master.stop_child(sender)
    stream.close()
    driver.close()
    for name in ['store_forward_sender', *instance_names(MODULE).values()]:
        ros.master.call('deleteParam', f'/{name}')


def test_a_failover_from_an_older_state_gets_every_measurement_again_from_the_relay(relay):
    from cnr_maps.measurements import read_tsv
    from test_local_mapcell_manager_migration import key
    start, driver, stream, sender, tmp = relay
    proc_a = start('robot')
    driver.promote(host='robot')
    driver.wait_active(10, host='robot')
    stream.start(rate=20.0)
    wait_until(lambda: stored(MODULE, 20), 30, 'A to store 20')
    replicated = driver.state(host='robot')                   # the newest state the manager holds
    held = len(replicated['measurements']['time'])
    wait_until(lambda: stored(MODULE, held + 15), 30, 'A to store (and acknowledge) beyond the replicated state')
    os.killpg(proc_a.pid, signal.SIGKILL)                     # lost: no freeze, no final state
    proc_a.wait(10)
    lost_at = len(stream.sent)
    stream.wait_sent(lost_at + 20)                            # published while no store runs
    proc_b = start('cloud')
    wait_until(lambda: driver.grantor.may_promote(time.monotonic()), 10, 'A\'s lease to run out')
    driver.promote(replicated, host='cloud')
    driver.wait_active(10, host='cloud')
    stream.wait_sent(len(stream.sent) + 20)
    stream.stop()
    sent = list(stream.sent)
    keys = stored_keys(f'{MODULE}_b', len(sent))
    assert keys == sent, (f'{len(set(sent) - set(keys))} of {len(sent)} missing, {len(keys) - len(set(keys))} '
                          f'duplicated; B: {proc_b.output()[-3000:]}')
    assert [key(m.time, m.x, m.y, m.temperature) for m in read_tsv(str(tmp / 'cloud.tsv'))] == sent
    assert held < lost_at and 'Traceback' not in proc_b.output(), proc_b.output()[-3000:]
    assert 'sending from seq' in sender.output()              # the sender went back to B's mark


def test_a_migration_hands_over_the_mark_and_nothing_comes_twice(relay):
    """A frozen, B promoted with A's final state while the stream goes on: B continues after A's mark; A takes
    and acknowledges nothing after its freeze."""
    start, driver, stream, _sender, tmp = relay
    start('robot')
    driver.promote(host='robot')
    driver.wait_active(10, host='robot')
    proc_b = start('cloud')
    stream.start(rate=20.0)
    wait_until(lambda: stored(MODULE, 20), 30, 'A to store 20')
    state = driver.freeze(host='robot')
    assert state['relay']['delivered'] == len(state['measurements']['time']) >= 20
    stream.wait_sent(len(stream.sent) + 10)                   # published between the freeze and the promotion
    driver.promote(state, host='cloud')
    driver.wait_active(10, host='cloud')
    stream.wait_sent(len(stream.sent) + 20)
    stream.stop()
    sent = list(stream.sent)
    keys = stored_keys(f'{MODULE}_b', len(sent))
    assert keys == sent, f'{len(set(sent) - set(keys))} of {len(sent)} missing, {len(keys) - len(set(keys))} duplicated'
    from cnr_maps.measurements import read_tsv
    assert len(read_tsv(str(tmp / 'robot.tsv'))) == len(state['measurements']['time'])   # A: nothing after it
    assert 'Traceback' not in proc_b.output()
