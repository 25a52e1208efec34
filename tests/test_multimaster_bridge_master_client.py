"""The bridge's client of its local master against a real rosmaster (port 0): an unchanged graph costs one
request and no parsing; any change in the graph gives a new snapshot with it."""
import xmlrpc.client

from cnr_harness import RosMaster
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
