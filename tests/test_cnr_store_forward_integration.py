"""cnr_store_forward on one real master: a publisher of cnr_msgs/MergedMeasurement (this test) -> sender ->
receiver -> a consumer (this test). The receiver is stopped (an outage) while publishing goes on, the sender is
killed with SIGKILL with records queued and again with records in flight, and both are restarted: the consumer
gets every measurement exactly once and in order. Parameters from config/store_forward.yaml with a few changes
(queues in a temporary directory, faster timeouts)."""
import os
import signal
import subprocess

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')

IN, OUT = '/sf_test/in', '/sf_test/out'


def params(workspace, tmp, stream, sender=None, receiver=None):
    from cnr_params import load_yaml
    out = load_yaml(os.path.join(workspace, 'config', 'store_forward.yaml'))
    out.update(stream=stream, status_rate=10.0)
    out['sender'].update(input_topic=IN, queue_dir=os.path.join(tmp, 'queue'), sync_period=0.02, rate=50.0,
                         batch_records=10, window=40, ack_timeout=0.5, max_backoff=1.0, **(sender or {}))
    out['receiver'].update(output_topic=OUT, state_dir=os.path.join(tmp, 'state'), **(receiver or {}))
    return out


class Stream:
    """The sender and receiver nodes of one stream (restartable), the test's publisher, consumer and the
    sender's latest status."""

    def __init__(self, ros, workspace, tmp, stream='itest', **changes):
        from cnr_msgs.msg import MergedMeasurement, StoreForwardStatus
        self.ros = ros
        self.names = {'sender': f'sf_sender_{stream}', 'receiver': f'sf_receiver_{stream}'}
        for name in self.names.values():
            ros.master.call('setParam', f'/{name}', params(workspace, tmp, stream, **changes))
        self.procs = {}
        self.got = []
        self.status = None
        self.pub = rospy.Publisher(IN, MergedMeasurement, queue_size=1000)
        self.subs = [rospy.Subscriber(OUT, MergedMeasurement, self.got.append, queue_size=None),
                     rospy.Subscriber(f'/{self.names["sender"]}/status', StoreForwardStatus,
                                      lambda m: setattr(self, 'status', m))]
        self.published = 0

    def start(self, role):
        name = self.names[role]
        self.procs[role] = self.ros.master.run(['rosrun', 'cnr_store_forward', role, f'__name:={name}'], name)
        if role == 'sender':
            wait_until(lambda: self.pub.get_num_connections() == 1, 30, 'the sender subscribed', self.procs[role])

    def stop(self, role):
        self.ros.master.stop_child(self.procs.pop(role))

    def kill(self, role):
        """SIGKILL: no shutdown code runs."""
        proc = self.procs.pop(role)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
        self.ros.master.stop_child(proc)
        if role == 'sender':
            wait_until(lambda: self.pub.get_num_connections() == 0, 30, 'the killed sender disconnected')

    def publish(self, count):
        from cnr_msgs.msg import MergedMeasurement
        for _ in range(count):
            self.published += 1
            m = MergedMeasurement(temperature=float(self.published), cell=-1)
            m.header.stamp = rospy.Time(self.published)
            self.pub.publish(m)

    def sender_status(self, condition, what, timeout=30):
        return wait_until(lambda: self.status if self.status is not None and condition(self.status) else None,
                          timeout, what, self.procs.get('sender'))

    def received(self):
        return [int(m.temperature) for m in self.got]

    def close(self):
        for sub in self.subs:
            sub.unregister()
        self.pub.unregister()
        for role in list(self.procs):
            self.stop(role)
        for name in self.names.values():
            self.ros.master.call('deleteParam', f'/{name}')


@pytest.fixture
def stream(ros, workspace, tmp_path):
    s = Stream(ros, workspace, str(tmp_path))
    yield s
    s.close()


def test_every_measurement_arrives_once_in_order_across_an_outage_and_sender_kills(stream):
    stream.start('receiver')
    stream.start('sender')
    stream.publish(30)
    wait_until(lambda: len(stream.got) >= 30, 30, '30 measurements relayed', stream.procs['sender'])
    # the receiver delivers before the sender hears its ack: stop it only once all 30 are acknowledged
    stream.sender_status(lambda s: s.acked_seq == 30 and s.queued == 0, 'the first 30 acknowledged')

    stream.stop('receiver')                                    # outage: the cloud side is gone
    stream.publish(50)
    st = stream.sender_status(lambda s: s.appended == 80 and s.queued == 50, '50 records queued')
    assert st.acked_seq == 30 and st.last_seq == 80 and st.oldest_unacked_age > 0 and not st.full

    stream.kill('sender')                                      # crash with 50 records queued
    stream.start('sender')
    st = stream.sender_status(lambda s: s.queued == 50 and s.appended == 0, 'the restarted sender with its queue')
    assert (st.acked_seq, st.last_seq) == (30, 80)

    stream.start('receiver')                                   # the link returns
    stream.publish(70)
    wait_until(lambda: len(stream.got) >= 100, 60, 'delivery after the outage', stream.procs['sender'])
    stream.kill('sender')                                      # crash with records in flight
    stream.start('sender')
    stream.publish(50)
    wait_until(lambda: len(stream.got) >= 200, 60, 'all 200 measurements', stream.procs['sender'])
    stream.sender_status(lambda s: s.queued == 0 and s.last_seq == 200, 'everything acknowledged')
    assert stream.received() == list(range(1, 201))
    assert [m.header.stamp.secs for m in stream.got] == list(range(1, 201))


def test_a_full_queue_refuses_new_records_and_reports_it(ros, workspace, tmp_path):
    s = Stream(ros, workspace, str(tmp_path), stream='full', sender={'max_records': 5})
    try:
        s.start('sender')                                      # no receiver: nothing is acknowledged
        s.publish(8)
        st = s.sender_status(lambda x: x.rejected == 3, '3 records refused')
        assert st.full and st.queued == 5 and st.last_seq == 5
        wait_until(lambda: 'queue FULL' in s.procs['sender'].output(), 10, 'the error in the log')
        assert s.procs['sender'].output().count('queue FULL') == 1
        s.start('receiver')
        wait_until(lambda: len(s.got) == 5, 30, 'the 5 stored records delivered')
        s.sender_status(lambda x: not x.full and x.queued == 0, 'room again')
        assert s.received() == [1, 2, 3, 4, 5]
    finally:
        s.close()


def test_missing_parameter_exits_2_naming_it(ros, workspace, tmp_path):
    bad = params(workspace, str(tmp_path), 'bad')
    del bad['sender']['window']
    ros.master.call('setParam', '/sf_bad', bad)
    try:
        r = subprocess.run(['rosrun', 'cnr_store_forward', 'sender', '__name:=sf_bad'],
                           env=ros.master.env, capture_output=True, text=True, timeout=60)
    finally:
        ros.master.call('deleteParam', '/sf_bad')
    assert r.returncode == 2
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and '/sf_bad: sender.window: missing' in lines[0], r.stderr


def test_a_relayed_message_is_never_relayed_again(ros, tmp_path):
    """The receiver publishes on the sender's input topic (on two masters: the output topic bridged back to the
    robot): the sender recognises the relay's connection header and ignores those messages. Both nodes come
    from store_forward.launch with the shipped config."""
    from cnr_msgs.msg import MergedMeasurement, StoreForwardStatus
    got, status = [], []
    pub = rospy.Publisher(IN, MergedMeasurement, queue_size=100)
    subs = [rospy.Subscriber(IN, MergedMeasurement, got.append, queue_size=None),
            rospy.Subscriber('/sf_sender_loop/status', StoreForwardStatus, status.append)]
    common = ['stream:=loop', f'input_topic:={IN}', f'output_topic:={IN}', f'queue_dir:={tmp_path}/q',
              f'state_dir:={tmp_path}/s']
    procs = []
    try:
        for role in ('receiver', 'sender'):                   # one after the other: roslaunch sets /run_id
            procs.append(ros.master.roslaunch('cnr_store_forward', 'store_forward.launch', f'role:={role}',
                                              f'node_name:=sf_{role}_loop', *common))
            wait_until(lambda: f'/sf_{role}_loop' in ros.master.node_names(), 60, f'the {role}', procs[-1])
        wait_until(lambda: pub.get_num_connections() == 2, 60, 'the sender subscribed', procs[1])
        for i in range(1, 6):
            pub.publish(MergedMeasurement(temperature=float(i)))
        wait_until(lambda: status and status[-1].ignored == 5 and status[-1].queued == 0, 60,
                   'the relayed copies ignored', procs[1])
        assert status[-1].last_seq == 5 and status[-1].appended == 5
        assert sorted(int(m.temperature) for m in got) == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5]   # direct + relayed once
    finally:
        for sub in subs:
            sub.unregister()
        pub.unregister()
        for proc in procs:
            ros.master.stop_child(proc)
