"""A managed module instance on one real master, driven through the real lease protocol by the test
(tests/migration_driver.py): passive as a standby, active only after its first granted renewal, its state
handed over on promotion and returned on freeze, silent once cut off. global_goal_manager here; the other
modules' instances have tests of their own."""
import math
import os
import time

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


def cell_states():
    from cnr_msgs.msg import CellState, CellStates
    msg = CellStates(rows=2, cols=4, cell_size=1.0)
    for i in range(8):
        r, c = divmod(i, 4)
        msg.cells.append(CellState(index=i, row=r, col=c, min_x=c, max_x=c + 1.0, min_y=r, max_y=r + 1.0,
                                   center_x=c + 0.5, center_y=r + 0.5, last_visit=rospy.Time(0)))
    return msg


@pytest.fixture
def gg(ros, workspace, request):
    """The managed global_goal_manager on the robot (or the host given as the fixture's indirect parameter)."""
    from cnr_msgs.msg import CellStates
    from migration_driver import LeaseDriver, managed_params
    host = getattr(request, 'param', 'robot')
    ros.master.call('setParam', '/global_goal_manager', {
        'frame_id': 'map', 'global_goal_manager': {'policy': 'coverage_sweep'},
        'migration': managed_params(workspace, host)})
    pub = rospy.Publisher('/cell_states', CellStates, queue_size=1, latch=True)
    pub.publish(cell_states())
    driver = LeaseDriver('global_goal_manager', host)
    proc = ros.master.run(['rosrun', 'global_goal_manager', 'global_goal_manager'], 'gg_managed')
    yield proc, driver
    ros.master.stop_child(proc)
    driver.close()
    pub.unregister()
    ros.master.call('deleteParam', '/global_goal_manager')


def next_goal(timeout=1.0):
    from cnr_msgs.srv import NextGoal
    rospy.wait_for_service('/global_goal_manager/next_goal', timeout)
    return rospy.ServiceProxy('/global_goal_manager/next_goal', NextGoal)(0.5, 0.5)


def served():
    try:
        rospy.wait_for_service('/global_goal_manager/next_goal', 0.2)
        return True
    except rospy.ROSException:
        return False


def test_standby_promotion_state_freeze_and_cut_off(gg):
    proc, driver = gg
    driver.wait_standby(30)
    assert not served()                                    # a standby serves nothing
    driver.promote({'policy': 'coverage_sweep', 'policy_state': {'waypoint_index': 2}, 'last_goal': 7})
    driver.wait_active(10)
    wait_until(served, 10, 'the promoted instance to serve')
    res = next_goal()
    # coverage sweep over 2x4 cells: waypoints 0, 3, 7, 4; handed over at index 2 -> the next is index 3
    assert res.success and res.cell.index == 4, res
    assert driver.state()['policy_state'] == {'waypoint_index': 3}

    state = driver.freeze()                                # frozen: outputs closed for good
    assert state['last_goal'] == 4 and state['policy_state'] == {'waypoint_index': 3}
    wait_until(lambda: not served(), 10, 'the frozen instance to stop serving')
    assert proc.alive()


def test_a_standby_reports_the_replica_it_holds_and_answers_a_ping_without_its_state(gg):
    """Before it freezes the source the manager waits (timeouts.replica) for the target standby to hold a replica
    of it: the standby's status names whose replicas it holds and the newest; a standby that gets patches to a
    replica it does not hold asks the active instance for a whole one. ``ping``, the manager's readiness probe,
    answers ready without the state (``state`` encodes it: the whole store, for local_mapcell_manager)."""
    from cnr_msgs.msg import InstanceStatus, ModuleState
    from cnr_msgs.srv import InstanceControl, InstanceControlResponse
    from migration_manager.core import state as codec
    proc, driver = gg
    st = driver.wait_standby(30)
    assert (st.replica_of, st.replica_seq) == ('', 0)
    control = rospy.ServiceProxy('/migration/global_goal_manager/robot/control', InstanceControl)
    ping, state = control(command='ping'), control(command='state')
    assert (ping.ok, ping.message, bytes(ping.state)) == (True, 'ready', b'') and len(state.state) > 0
    asked = []                                   # the cloud instance's control service, as the standby sees it
    cloud = rospy.Service('/migration/global_goal_manager/cloud/control', InstanceControl,
                          lambda req: asked.append(req.command) or InstanceControlResponse(ok=True))
    pub = rospy.Publisher('/migration/global_goal_manager/state', ModuleState, queue_size=5)
    try:
        wait_until(lambda: pub.get_num_connections() > 0, 10, 'the standby to follow the replicas')
        # a patch to a replica it does not hold (its subscription connected after the whole state): it asks for one
        pub.publish(ModuleState(module='global_goal_manager', instance='global_goal_manager@cloud', term=1, seq=6,
                                base_seq=5, data=codec.encode_patch('global_goal_manager', 5, {'last_goal': 3})))
        wait_until(lambda: 'keyframe' in asked, 10, 'a keyframe request to the cloud instance')
        data = codec.encode('global_goal_manager', {'policy': 'coverage_sweep', 'policy_state': {'waypoint_index': 2},
                                                    'last_goal': None})
        pub.publish(ModuleState(module='global_goal_manager', instance='global_goal_manager@cloud', term=1, seq=7,
                                base_seq=0, data=data))
        st = wait_until(lambda: driver.status if driver.status.replica_seq else None, 5,
                        'a status naming the replica held')
        assert (st.role, st.replica_of, st.replica_seq) == (InstanceStatus.STANDBY, 'global_goal_manager@cloud', 7)
    finally:
        pub.unregister()
        cloud.shutdown()


def test_a_cut_off_instance_closes_its_outputs_and_a_bad_state_is_refused(gg):
    from cnr_msgs.srv import InstanceControl
    from migration_manager.core import state as codec
    proc, driver = gg
    driver.wait_standby(30)
    control = rospy.ServiceProxy('/migration/global_goal_manager/robot/control', InstanceControl)
    bad = control(command='promote', term=1, state=codec.encode('global_goal_manager', {'policy': 'least_recently_visited'}))
    assert not bad.ok and 'policy' in bad.message
    driver.promote()
    driver.wait_active(10)
    assert next_goal().success
    driver.cut_off()                                       # renewals unanswered: the lease runs out
    driver.wait_role('promoted', 5)
    res = next_goal()
    assert not res.success and 'not the active instance' in res.message
    assert proc.alive() and 'Traceback' not in proc.output()


def test_a_promotion_carrying_the_lease_of_a_standby_request_is_active_when_answered(gg):
    """The hot hand-over's fast path: a standby sends requests (term 0); the promotion grants its newest one, so
    the instance opens its outputs before it answers, without a round trip for its first renewal."""
    proc, driver = gg
    driver.wait_standby(30)
    wait_until(lambda: driver.instance in driver.grantor.standby, 10, 'a standby request from the instance')
    driver.promote(pregrant=True)
    assert driver.last_promotion_active
    assert next_goal().success                             # its service was registered before it answered
    driver.wait_active(5)


def test_an_instance_that_became_active_asks_the_bridge_to_poll_after_registering(gg, ros):
    """``bridge_poll_service`` (config/migration.yaml): the test plays this host's bridge."""
    from std_srvs.srv import Empty, EmptyResponse
    proc, driver = gg
    calls = []

    def on_poll(_req):
        # what the bridge's poll would find: the service on_active registered must already be there
        try:
            calls.append(bool(ros.master.call('lookupService', '/global_goal_manager/next_goal')))
        except RuntimeError:
            calls.append(False)
        return EmptyResponse()
    service = rospy.Service('/bridge/poll', Empty, on_poll)
    try:
        driver.wait_standby(30)
        assert calls == []                                 # a standby asks nothing
        driver.promote(None)
        driver.wait_active(10)
        wait_until(lambda: calls, 10, 'the promoted instance to ask the bridge to poll')
        assert calls == [True]
    finally:
        service.shutdown()


@pytest.mark.parametrize('gg', ['robot', 'cloud'], indirect=True)
def test_an_active_instance_replicates_less_often_on_the_authoritys_host(gg, workspace):
    """config/migration.yaml: the active instance publishes its state every replicate_period on the cloud, and
    every replicate_period_authority on the robot (the manager's host: a freeze reaches it without the link)."""
    from cnr_msgs.msg import ModuleState
    from cnr_params import load_yaml
    cfg = load_yaml(os.path.join(workspace, 'config', 'migration.yaml'))
    proc, driver = gg
    arrivals = []
    sub = rospy.Subscriber('/migration/global_goal_manager/state', ModuleState,
                           lambda m: arrivals.append(time.monotonic()), queue_size=50)
    try:
        driver.wait_standby(30)
        driver.promote({'policy': 'coverage_sweep', 'policy_state': {'waypoint_index': 0}, 'last_goal': None})
        driver.wait_active(10)
        if driver.host == cfg['authority']:
            period = cfg['replicate_period_authority']
            wait_until(lambda: len(arrivals) >= 2, 3 * period, 'two replicas on the robot')
            assert arrivals[1] - arrivals[0] >= 0.8 * period, arrivals
        else:
            period = cfg['replicate_period']
            wait_until(lambda: len(arrivals) >= 4, 10 * period, 'four replicas on the cloud')
            gaps = [b - a for a, b in zip(arrivals, arrivals[1:4])]
            assert max(gaps) < 2 * period, gaps
    finally:
        sub.unregister()
