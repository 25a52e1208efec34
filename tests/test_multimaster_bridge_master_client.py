"""The bridge's client of its local master against a real rosmaster (port 0): an unchanged graph costs one
request and no parsing; any change in the graph gives a new snapshot with it."""
import os
import subprocess
import time
import xmlrpc.client

from cnr_harness import RosMaster, wait_until
from multimaster_bridge.core import sync
from multimaster_bridge.node import MasterClient


def test_an_unchanged_graph_gives_the_same_snapshot_and_a_change_a_new_one():
    with RosMaster() as master:
        px = xmlrpc.client.ServerProxy(master.uri)
        px.registerPublisher('/talker', '/chatter', 'std_msgs/String', 'http://127.0.0.1:10001/')
        client = MasterClient(master.uri, '/bridge')
        first = client.snapshot(None, True)
        assert first.types['/chatter'] == 'std_msgs/String' and first.nodes['/talker'] == 'http://127.0.0.1:10001/'
        assert client.snapshot(first, False) is first
        assert client.snapshot(first, True) is not first        # a refresh is never skipped

        px.registerPublisher('/other', '/scan', 'sensor_msgs/LaserScan', 'http://127.0.0.1:10002/')
        second = client.snapshot(first, False)
        assert second is not first
        assert second.types['/scan'] == 'sensor_msgs/LaserScan' and second.nodes['/other'] == 'http://127.0.0.1:10002/'
        assert client.snapshot(second, False) is second

        px.unregisterPublisher('/other', '/scan', 'http://127.0.0.1:10002/')
        third = client.snapshot(second, False)
        assert '/scan' not in third.pubs and '/other' not in third.node_names()
        client.reset()                                          # a new connection parses afresh
        fourth = client.snapshot(third, False)
        assert fourth is not third and fourth == third


def test_a_subscribed_only_topic_keeps_its_type_between_refreshes():
    """Its type comes from getTopicTypes at a refresh; a poll in between must not drop it (the exported state
    would flip between the type and '*', and the peer re-register the subscriber proxy each time)."""
    with RosMaster() as master:
        px = xmlrpc.client.ServerProxy(master.uri)
        px.registerPublisher('/talker', '/chatter', 'std_msgs/String', 'http://127.0.0.1:10001/')
        px.registerSubscriber('/listener', '/cmd', 'geometry_msgs/Twist', 'http://127.0.0.1:10002/')
        client = MasterClient(master.uri, '/bridge')
        first = client.snapshot(None, True)
        assert first.types == {'/chatter': 'std_msgs/String', '/cmd': 'geometry_msgs/Twist'}
        px.registerSubscriber('/other', '/chatter', 'std_msgs/String', 'http://127.0.0.1:10003/')   # no new topic
        second = client.snapshot(first, False)
        assert second is not first and second.types == first.types
        px.unregisterSubscriber('/listener', '/cmd', 'http://127.0.0.1:10002/')
        assert client.snapshot(second, False).types == {'/chatter': 'std_msgs/String'}


def test_a_service_with_a_new_provider_gets_the_new_providers_uri_between_refreshes():
    """A migrated service: the old instance's registration replaced by the new one's (another node) between two
    polls; the new one was known already (a standby: it subscribes before it is promoted). The snapshot must carry
    the new URI at once, not the cached one until the next refresh (the peer would register its proxy pointing at
    the old instance: calls failed for up to a second)."""
    with RosMaster() as master:
        px = xmlrpc.client.ServerProxy(master.uri)
        px.registerService('/robot/ggm', '/next_goal', 'rosrpc://127.0.0.1:20001', 'http://127.0.0.1:10001/')
        px.registerPublisher('/talker', '/chatter', 'std_msgs/String', 'http://127.0.0.1:10003/')
        px.registerSubscriber('/ggm', '/chatter', 'std_msgs/String', 'http://127.0.0.1:10002/')   # the standby
        client = MasterClient(master.uri, '/bridge')
        first = client.snapshot(None, True)
        assert first.service_apis['/next_goal'] == 'rosrpc://127.0.0.1:20001'
        px.registerService('/ggm', '/next_goal', 'rosrpc://127.0.0.1:20002', 'http://127.0.0.1:10002/')
        second = client.snapshot(first, False)
        assert second.services['/next_goal'] == '/ggm'
        assert second.service_apis['/next_goal'] == 'rosrpc://127.0.0.1:20002'
        assert second.nodes['/ggm'] == 'http://127.0.0.1:10002/'
        assert second.nodes['/talker'] == 'http://127.0.0.1:10003/'      # kept from before


def test_a_node_the_master_still_holds_keeps_its_uri_spelling_and_the_real_node_lives():
    """rosmaster keeps a node while any registration lists it; a proxy's service that a local provider took over
    stays listed after the proxy's removal. The bridge's forced reconnect (the other URI spelling) would then
    make rosmaster shut down the URI it holds — the real remote node (here a real rostopic process whose URI the
    proxy carries). node_apis sees the entry, kept_spellings keeps the master's spelling, the node lives; the
    other spelling, as the bridge registered it before, shuts it down."""
    with RosMaster() as master:
        env = dict(os.environ, ROS_MASTER_URI=master.uri)
        node = subprocess.Popen(['rostopic', 'pub', '-r', '5', '/chatter', 'std_msgs/String', 'data: x',
                                 '__name:=dual'], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            px = xmlrpc.client.ServerProxy(master.uri)
            wait_until(lambda: px.lookupNode('/test', '/dual')[0] == 1, 30, 'the real node')
            uri = px.lookupNode('/test', '/dual')[2]
            # its proxy (as another bridge names it), with a service a newer local provider then takes over
            px.registerPublisher('/robot/dual', '/chatter_proxy', 'std_msgs/String', uri)
            px.registerService('/robot/dual', '/echo', 'rosrpc://127.0.0.1:1', uri)
            px.registerService('/server', '/echo', 'rosrpc://127.0.0.1:2', 'http://127.0.0.1:3/')
            # the peer lost: the proxy's registrations removed (the service's no longer matches)
            px.unregisterService('/robot/dual', '/echo', 'rosrpc://127.0.0.1:1')
            px.unregisterPublisher('/robot/dual', '/chatter_proxy', uri)
            client = MasterClient(master.uri, '/bridge')
            known = client.node_apis(['/robot/dual', '/nobody'])
            assert known == {'/robot/dual': uri}
            other = sync.uri_spelling(uri, 1)
            kept = sync.kept_spellings({'/robot/dual': other}, known)
            assert kept == {'/robot/dual': uri}
            px.registerPublisher('/robot/dual', '/chatter_proxy', 'std_msgs/String', kept['/robot/dual'])
            time.sleep(1.0)        # a shutdown would be on its way at once (the master's thread pool)
            assert node.poll() is None, 'the real node was shut down'
            # the other spelling: rosmaster tells "the old node" - the real one - to shut down
            px.unregisterPublisher('/robot/dual', '/chatter_proxy', uri)
            px.registerPublisher('/robot/dual', '/chatter_proxy', 'std_msgs/String', other)
            wait_until(lambda: node.poll() is not None, 15, 'rosmaster to shut the real node down')
        finally:
            if node.poll() is None:
                node.kill()
            node.wait()


def test_a_remote_node_started_again_replaces_the_entry_a_taken_over_service_kept():
    """The old process's proxy left an entry the bridge cannot remove (its service, taken over by a local provider).
    The node, started again on its host at a new URI, is registered there at once (must_wait): the master then
    holds the new URI, and subscribers are given the new publisher, not the dead one."""
    with RosMaster() as master:
        px = xmlrpc.client.ServerProxy(master.uri)
        old, new = 'http://127.0.0.1:38921/', 'http://127.0.0.1:39863/'
        px.registerPublisher('/cloud/ggm', '/global_goal', 'std_msgs/String', old)
        px.registerService('/cloud/ggm', '/next_goal', 'rosrpc://127.0.0.1:1', old)
        px.registerService('/ggm', '/next_goal', 'rosrpc://127.0.0.1:2', 'http://127.0.0.1:3/')   # failed over here
        client = MasterClient(master.uri, '/bridge')
        gone = [sync.Registration('pub', '/global_goal', '/cloud/ggm', old, 'std_msgs/String'),
                sync.Registration('srv', '/next_goal', '/cloud/ggm', old, 'rosrpc://127.0.0.1:1')]
        client.apply(gone, [])
        assert client.node_apis(['/cloud/ggm']) == {'/cloud/ggm': old}     # held for ever by the service entry
        assert not sync.must_wait(old, new)
        again = sync.Registration('pub', '/global_goal', '/cloud/ggm', new, 'std_msgs/String')
        assert client.apply([], [again]) == []
        assert client.node_apis(['/cloud/ggm']) == {'/cloud/ggm': new}
        pubs = dict(px.getSystemState('/test')[2][0])
        assert pubs['/global_goal'] == ['/cloud/ggm']
        assert px.lookupNode('/test', '/cloud/ggm')[2] == new
