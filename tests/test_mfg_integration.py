"""mfg with the global goal manager gone (as when it runs on the cloud and the link is down): the robot keeps
patrolling with its own goals at once, and never waits on the missing service. Real master, real nodes."""
import subprocess
import threading

import pytest

from cnr_harness import wait_until
from mfg_missions import patrol_only_mission

rospy = pytest.importorskip('rospy')


@pytest.fixture
def mission(ros, workspace, tmp_path):
    """The corridor without heaters: mfg only patrols (no hotspot search, no end of the mission)."""
    proc, _report = patrol_only_mission(ros, workspace, tmp_path, 'mfg_fallback', 'real_time_factor:=4')
    yield proc
    proc.stop()


def test_patrol_goes_on_with_local_goals_when_the_global_goal_manager_is_gone(mission, ros):
    from cnr_msgs.msg import SearchState
    states = []
    lock = threading.Lock()

    def on_state(msg):
        with lock:
            states.append((msg.mode, msg.message, msg.goal_cell))
    sub = rospy.Subscriber('mfg/state', SearchState, on_state, queue_size=50)
    try:
        def patrol_goals(tag):
            with lock:
                return [s for s in states if s[0] == 'PATROL' and s[2] >= 0 and tag in s[1]]
        wait_until(lambda: patrol_goals('[least_recently_visited]'), 120, 'a goal from the global goal manager',
                   mission)
        subprocess.run(['rosnode', 'kill', '/global_goal_manager'], env=ros.master.env, check=True,
                       capture_output=True, timeout=30)
        # the next goals come from the robot itself; the patrol does not stop
        wait_until(lambda: len(patrol_goals('(local fallback)')) >= 2, 180,
                   'two goals of the local fallback after the global goal manager was killed', mission)
        fallback = patrol_goals('(local fallback)')
        assert fallback[0][2] != fallback[1][2], fallback
        out = mission.output()
        assert out.count('global goal manager unavailable') == 1, out[-3000:]      # logged once
        assert 'Traceback' not in out, out[-3000:]
    finally:
        sub.unregister()
