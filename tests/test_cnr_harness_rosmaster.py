"""cnr_harness.rosmaster's NodeDispatcher, rosmaster's notification pool per node: one node's calls in order, at most
the pool's size at once, a hung call never holding up another node's, no thread while there is no work. ROS-free
(no master)."""
import threading
import time

from cnr_harness import wait_until
from cnr_harness.rosmaster import NodeDispatcher


def test_a_hung_node_holds_up_only_its_own_calls():
    pool = NodeDispatcher(3, hang_after=0.2)
    release = threading.Event()
    done = []
    for i in range(8):                      # more hung nodes than rosmaster's 3 threads
        pool.queue_task(f'http://cloud:{i}/', release.wait, (60,))
    pool.queue_task('http://robot:1/', done.append, ('local',))
    wait_until(lambda: done == ['local'], 2.0, 'the local node\'s call behind 8 hung ones')
    release.set()
    wait_until(lambda: pool.pending() == 0 and pool.get_thread_count() == 0, 5.0, 'the hung calls to end')


def test_one_node_s_calls_run_in_order_and_report_their_results():
    pool = NodeDispatcher(3, hang_after=0.2)
    gate = threading.Event()
    order, results = [], []
    pool.queue_task('n', gate.wait, (5,))
    for i in range(5):
        pool.queue_task('n', order.append, (i,), results.append)
    gate.set()
    wait_until(lambda: order == [0, 1, 2, 3, 4], 5.0, 'the calls in order')
    wait_until(lambda: len(results) == 5, 5.0, 'the callbacks')


def test_a_failing_call_is_logged_and_the_next_one_runs(caplog):
    pool = NodeDispatcher(3, hang_after=0.2)
    done = []
    pool.queue_task('n', lambda: 1 / 0)
    pool.queue_task('n', done.append, ('next',))
    wait_until(lambda: done == ['next'], 5.0, 'the call after a failing one')
    assert 'ZeroDivisionError' in caplog.text


def test_at_most_the_pool_s_size_of_answering_calls_run_at_once():
    pool = NodeDispatcher(3, hang_after=5.0)
    lock, running, most = threading.Lock(), [0], [0]

    def call():
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        time.sleep(0.1)
        with lock:
            running[0] -= 1
    for i in range(9):
        pool.queue_task(f'http://robot:{i}/', call)
    wait_until(lambda: pool.pending() == 0, 5.0, 'the nine calls')
    assert most[0] == 3


def test_after_join_all_nothing_is_queued():
    pool = NodeDispatcher(3)
    pool.join_all(wait_for_tasks=False, wait_for_threads=False)
    assert pool.queue_task('n', print, ('x',)) is False and pool.pending() == 0


def test_a_multicall_s_notifications_start_once_it_is_answered_and_only_the_newest_list_per_topic_is_sent():
    from cnr_harness.rosmaster import hold_during_multicall, publisher_update_task
    pool = NodeDispatcher(3, hang_after=0.2)
    assert pool._superseded is publisher_update_task() is not None   # rosmaster's publisherUpdate task
    sent = []
    pool._superseded = sent_update = lambda api, topic, pubs: sent.append((api, topic, pubs))   # records instead

    def multicall(_server, calls):                          # stands for SimpleXMLRPCDispatcher.system_multicall
        for api, topic, pubs in calls:                      # one registration each: its subscribers notified
            pool.queue_task(api, sent_update, (api, topic, pubs))
        assert sent == [] and pool.get_thread_count() == 0  # nothing sent while the multicall runs
        return ['ok'] * len(calls)
    calls = [('http://robot:1/', '/scan', ['a']), ('http://robot:2/', '/scan', ['a']),
             ('http://robot:1/', '/scan', ['a', 'b']), ('http://robot:1/', '/odom', ['c']),
             ('http://robot:1/', '/scan', ['a', 'b', 'd'])]
    assert hold_during_multicall(multicall)(None, calls) == ['ok'] * 5
    wait_until(lambda: pool.pending() == 0, 5.0, 'the held notifications')
    # robot:1 hears of /scan once, with the newest list, before /odom (its order); robot:2 once
    assert [x for x in sent if x[0] == 'http://robot:1/'] == [('http://robot:1/', '/scan', ['a', 'b', 'd']),
                                                             ('http://robot:1/', '/odom', ['c'])]
    assert [x for x in sent if x[0] == 'http://robot:2/'] == [('http://robot:2/', '/scan', ['a'])]


def test_a_running_notification_is_not_superseded_and_other_tasks_never_are():
    pool = NodeDispatcher(3, hang_after=5.0)
    gate, sent = threading.Event(), []

    def update(api, topic, pubs):
        gate.wait(5)
        sent.append(pubs)
    pool._superseded = update
    pool.queue_task('n', update, ('n', '/t', ['a']))         # running (waits at the gate)
    wait_until(lambda: pool.pending() == 1, 2.0, 'the first update to start')
    pool.queue_task('n', update, ('n', '/t', ['a', 'b']))
    pool.queue_task('n', update, ('n', '/t', ['a', 'b', 'c']))   # supersedes the queued one, not the running one
    pool.queue_task('n', sent.append, ('other',))
    pool.queue_task('n', sent.append, ('other',))            # not a publisher update: both run
    gate.set()
    wait_until(lambda: pool.pending() == 0, 5.0, 'the updates')
    assert sent == [['a'], ['a', 'b', 'c'], 'other', 'other']



def test_a_graph_query_is_told_apart_from_other_calls_and_from_odd_requests():
    import xmlrpc.client
    from cnr_harness.rosmaster import GraphAnswers
    assert GraphAnswers.query(xmlrpc.client.dumps(('/w',), 'getSystemState').encode()) == b'getSystemState'
    assert GraphAnswers.query(xmlrpc.client.dumps(('/w',), 'getTopicTypes').encode()) == b'getTopicTypes'
    assert GraphAnswers.query(xmlrpc.client.dumps(('/w', ''), 'getPublishedTopics').encode()) is None
    # a call rosmaster answers with an error goes to it as it is
    assert GraphAnswers.query(xmlrpc.client.dumps(('/w', 'extra'), 'getSystemState').encode()) is None
    multi = xmlrpc.client.dumps(([{'methodName': 'getSystemState', 'params': ['/w']}],), 'system.multicall').encode()
    assert GraphAnswers.query(multi) is None


def test_the_master_s_kept_answers_follow_every_change_of_the_graph(tmp_path):
    """A real cnr_harness.rosmaster: getSystemState and getTopicTypes answer from what it keeps, and each kind of
    change — a registration, an unregistration, a MultiCall of them, a node at a new URI (rosmaster drops its old
    registrations) — shows in the very next answer."""
    import xmlrpc.client
    from cnr_harness import RosMaster, master_proxy
    with RosMaster(str(tmp_path), multi_master=True) as master:
        m = master_proxy(master.uri, 10.0, compressed=False)

        def topics(kind=0):
            code, _, state = m.getSystemState('/t')
            assert code == 1
            return {t: sorted(nodes) for t, nodes in state[kind]}

        assert '/a' not in topics()
        m.registerPublisher('/n1', '/a', 'std_msgs/String', 'http://127.0.0.1:1/')
        assert topics()['/a'] == ['/n1']
        assert topics()['/a'] == ['/n1']                        # kept: the same answer again
        assert ['/a', 'std_msgs/String'] in m.getTopicTypes('/t')[2]
        multi = xmlrpc.client.MultiCall(m)
        multi.registerSubscriber('/n2', '/a', 'std_msgs/String', 'http://127.0.0.1:2/')
        multi.registerService('/n2', '/s', 'rosrpc://127.0.0.1:3', 'http://127.0.0.1:2/')
        multi.registerPublisher('/n2', '/b', 'std_msgs/Int32', 'http://127.0.0.1:2/')
        list(multi())
        assert topics(1)['/a'] == ['/n2'] and topics(2)['/s'] == ['/n2'] and topics()['/b'] == ['/n2']
        assert ['/b', 'std_msgs/Int32'] in m.getTopicTypes('/t')[2]
        m.unregisterPublisher('/n1', '/a', 'http://127.0.0.1:1/')
        assert '/a' not in topics()
        m.registerPublisher('/n2', '/c', 'std_msgs/String', 'http://127.0.0.1:9/')   # /n2 at a new URI
        assert '/b' not in topics() and '/s' not in topics(2) and topics()['/c'] == ['/n2']
