"""The robot-side stand-in's decisions and the standstill measure, without ROS (mfg.core.standin)."""
import os

import pytest
import yaml

from cnr_params import ConfigError, Section
from mfg.core.standin import ACTIVE, Standin, Standstill, read_params

SUCCEEDED, PREEMPTED = 3, 2


@pytest.fixture
def params(workspace):
    return read_params(Section.from_file(os.path.join(workspace, 'config', 'goal_standin.yaml')))


def own(goal_id):
    return goal_id.startswith('/goal_standin-')


def feed(s, t0, t1, goals, heartbeat=True, step=0.2):
    """move_base's status lists at 5 Hz (and the source's heartbeat at 1 Hz) from t0 to t1."""
    t = t0
    while t < t1 - 1e-9:
        s.path.status(t, goals)
        if heartbeat and abs(t - round(t)) < 1e-6:
            s.path.heartbeat(t)
        t = round(t + step, 6)
    return t


def test_the_config_file_is_complete_and_a_missing_field_is_named(params, workspace):
    assert params.timeout + 0.5 <= 2.0          # a goal within (outage + 2 s): the timeout and the goal's way
    assert params.watch.source_silence > 2.0    # one lost 1 Hz heartbeat is not silence
    with open(os.path.join(workspace, 'config', 'goal_standin.yaml')) as f:
        data = yaml.safe_load(f)
    del data['standin']['timeout']
    with pytest.raises(ConfigError, match='x.yaml: standin.timeout: missing'):
        read_params(Section(data, 'x.yaml'))
    data['standin']['timeout'], data['standin']['hold_modes'] = 1.0, 'SEARCH'
    with pytest.raises(ConfigError, match='standin.hold_modes: must be a list'):
        read_params(Section(data, 'x.yaml'))


def test_no_goal_before_a_task_was_given(params):
    s = Standin(params, own)
    feed(s, 0.0, 10.0, [], heartbeat=False)
    assert s.path.standing_since(10.0) is None and not s.due(10.0)


def test_a_source_that_gives_no_more_goals_is_stood_in_for_after_the_timeout(params):
    s = Standin(params, own)
    t = feed(s, 0.0, 5.0, [('/mfg-1-0.0', ACTIVE)])
    t = feed(s, t, 5.0 + params.timeout - 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.path.standing_since(t) == pytest.approx(5.0) and not s.due(t)
    t = feed(s, t, t + 0.4, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.due(t)
    s.sent()
    assert s.standing_in


def test_a_live_searching_source_holds_the_robot_until_it_goes_silent(params):
    s = Standin(params, own)
    s.path.source_mode(0.0, 'SEARCH')
    t = feed(s, 0.0, 2.0, [('/mfg-1-0.0', ACTIVE)])
    t = feed(s, t, 12.0, [('/mfg-1-0.0', SUCCEEDED)])          # measuring a cell: no goal, on purpose
    assert s.path.holding(t) and s.path.standing_since(t) is None and not s.due(t)
    t = feed(s, t, 12.0 + params.watch.source_silence + 0.2, [('/mfg-1-0.0', SUCCEEDED)], heartbeat=False)
    # silent: standing still since its last heartbeat (12.0), and the stand-in drives at once
    assert s.path.standing_since(t) == pytest.approx(11.0) and s.due(t)


def test_a_live_source_holds_no_longer_than_the_stuck_timeout(params):
    s = Standin(params, own)
    s.path.source_mode(0.0, 'SEARCH')
    t = feed(s, 0.0, 1.0, [('/mfg-1-0.0', ACTIVE)])
    t = feed(s, t, 1.0 + params.watch.stuck_timeout + 0.2, [('/mfg-1-0.0', SUCCEEDED)])
    assert s.path.alive(t) and not s.path.holding(t) and s.due(t)
    assert s.path.standing_since(t) == pytest.approx(1.0)        # no hold after all: since the goal ended


def test_its_own_goals_follow_each_other_while_the_source_is_silent_and_a_source_goal_takes_over(params):
    s = Standin(params, own)
    t = feed(s, 0.0, 1.0, [('/mfg-1-0.0', ACTIVE)])
    t = feed(s, t, 4.0, [('/mfg-1-0.0', SUCCEEDED)], heartbeat=False)
    assert s.due(t)
    s.sent()
    t = feed(s, t, 9.0, [('/goal_standin-1-4.0', ACTIVE)], heartbeat=False)
    assert not s.due(t) and not s.handed_back()                  # its own goal is being driven to
    t = feed(s, t, 9.4, [('/goal_standin-1-4.0', SUCCEEDED)], heartbeat=False)
    assert s.due(t)                                               # the next one at once, no timeout
    s.sent()
    # the source speaks again and its goal preempts the stand-in's: handed back, once
    s.path.heartbeat(t)
    t = feed(s, t, t + 1.0, [('/goal_standin-2-9.4', PREEMPTED), ('/mfg-2-9.0', ACTIVE)])
    assert s.handed_back() and not s.handed_back() and not s.standing_in and not s.due(t)
    # its goal ends: the source gives the next one within the timeout, the stand-in waits
    t0 = t
    t = feed(s, t, t + params.timeout - 0.2, [('/mfg-2-9.0', SUCCEEDED)])
    assert not s.due(t) and s.path.standing_since(t) == pytest.approx(t0)


def test_a_stale_status_list_is_no_goal(params):
    """move_base on the cloud, its status no longer arriving: the robot's goal is unknown since the last list."""
    s = Standin(params, own)
    feed(s, 0.0, 3.0, [('/mfg-1-0.0', ACTIVE)])                   # last list at 2.8
    assert s.path.standing_since(2.8 + params.watch.status_stale - 0.1) is None
    assert s.path.standing_since(2.8 + params.watch.status_stale + 0.1) == pytest.approx(2.8)


def test_standstill_keeps_the_longest_interval_and_its_start():
    st = Standstill()
    st.sample(1.0, None, 0.0)
    for now in (2.0, 2.5, 3.0):
        st.sample(now, 1.5, 101.5)
    st.sample(3.2, None, 0.0)
    for now in (5.0, 6.0):
        st.sample(now, 4.0, 104.0)
    assert (st.longest, st.longest_since, st.longest_wall) == (2.0, 4.0, 104.0)
    assert st.intervals == 2 and st.total == pytest.approx(1.5 + 2.0) and st.open
    st.sample(6.1, None, 0.0)
    assert not st.open and st.total == pytest.approx(3.5)


def test_a_source_that_ends_its_search_gets_the_timeout_from_then_and_only_its_goal_stops_the_chain(params):
    s = Standin(params, own)
    s.path.source_mode(0.0, 'SEARCH')
    t = feed(s, 0.0, 1.0, [('/mfg-1-0.0', ACTIVE)])
    t = feed(s, t, 8.0, [('/mfg-1-0.0', SUCCEEDED)])          # measuring
    s.path.source_mode(t, 'PATROL')                           # done: its next goal is due within the timeout
    assert s.path.standing_since(t) == pytest.approx(8.0) and not s.due(t + params.timeout - 0.1)
    assert s.due(t + params.timeout)
    s.sent()
    t = feed(s, t, t + 3.0, [('/goal_standin-1-9.5', ACTIVE)])
    t = feed(s, t, t + 0.4, [('/goal_standin-1-9.5', SUCCEEDED)])
    # the source is heard but its goal has not come (after an outage its registrations may still be restored on the
    # robot's master): the chain goes on, no second timeout of standing still
    assert s.path.alive(t) and s.due(t)
    s.sent()
    t = feed(s, t, t + 0.5, [('/goal_standin-2-9.9', ACTIVE), ('/mfg-2-10.0', ACTIVE)])
    assert s.handed_back() and not s.standing_in             # the source's goal is pursued: handed back
    t = feed(s, t, t + 0.4, [('/mfg-2-10.0', SUCCEEDED)])
    assert not s.due(t) and s.due(t + params.timeout)         # from now on the timeout again
