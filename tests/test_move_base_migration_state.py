"""move_base's migration state without ROS: the hand-over record round trip through the migration codec, a state
that does not fit refused with a ValueError naming its field, the recovery sequence continued and the patience
timers restarted after a pause (cnr_navigation.core.migration, cnr_navigation.core.move_base)."""
import copy
import math

import numpy as np
import pytest

from cnr_navigation.core.geometry import Pose2D, yaw_to_quaternion
from cnr_navigation.core.migration import GoalRecord, HandOver, parse_state, target_yaw
from cnr_navigation.core.move_base import MoveBaseConfig, MoveBaseCore, NavState
from cnr_navigation.core.recovery import Recovery, StepResult
from migration_manager.core import state as codec

GOAL = GoalRecord('/mfg-3-12.500', 1712, 500_000_000, 'map', 4.0, 0.4, 0.5, False, 2, 'CONTROLLING_R',
                  ((0.0, 0.0, 0.0), (2.0, 0.2, 0.1), (4.0, 0.4, 0.5)))
NEXT = GoalRecord('/mfg-4-13.000', 1713, 0, 'base_link', 1.0, -0.5, -1.0, True)


SEEN = ('/mfg-2-11.000', '/mfg-3-12.500', '/mfg-4-13.000')
CANCELS = (('', 0, 0), ('/mfg-2-11.000', 1711, 0))
HANDOVER = HandOver(GOAL, NEXT, SEEN, CANCELS)


def good_state():
    return HANDOVER.to_dict()


def test_round_trip_through_the_migration_codec():
    data = codec.encode('move_base', good_state())
    back = parse_state(codec.decode('move_base', data), recoveries=4)
    assert back == HANDOVER
    assert back.goal.recovery_index == 2 and back.goal.recovery_trigger == 'CONTROLLING_R'
    assert back.goal.plan == GOAL.plan
    # a pending goal carries no recovery state or plan of its own
    assert 'recovery_index' not in good_state()['next_goal'] and 'plan' not in good_state()['next_goal']
    older = good_state()
    del older['goal']['plan']                                     # an instance from before plans were handed over
    assert parse_state(older, 4).goal.plan == ()
    del older['seen_goals'], older['seen_cancels']                # ... or before what it received was
    assert parse_state(older, 4).seen_goals is None               # not known: the next replays nothing parked
    assert HandOver().seen_goals == ()                            # no state at all (a first start): nothing seen


def test_no_goal_is_a_valid_state_and_nan_targets_are_kept():
    assert parse_state({'goal': None, 'next_goal': None}, 4).empty
    odd = HandOver(GoalRecord('g', 0, 0, 'map', math.nan, math.inf, math.nan), None).to_dict()
    back = parse_state(codec.decode('move_base', codec.encode('move_base', odd)), 4)
    assert math.isnan(back.goal.x) and math.isinf(back.goal.y)     # refused by the next instance as move_base does


@pytest.mark.parametrize('change, field', [
    (lambda s: s.pop('goal'), 'goal is missing'),
    (lambda s: s.pop('next_goal'), 'next_goal is missing'),
    (lambda s: s.update(extra=1), "unknown key 'extra'"),
    (lambda s: s.update(goal=[1, 2]), 'goal must be an object'),
    (lambda s: s['goal'].pop('id'), 'goal.id'),
    (lambda s: s['goal'].update(id=''), 'goal.id'),
    (lambda s: s['goal'].update(stamp_secs=1.5), 'goal.stamp_secs'),
    (lambda s: s['goal'].update(stamp_nsecs=1_000_000_000), 'goal.stamp_nsecs'),
    (lambda s: s['goal'].update(frame=None), 'goal.frame'),
    (lambda s: s['goal'].update(x='4'), 'goal.x'),
    (lambda s: s['goal'].update(yaw=True), 'goal.yaw'),
    (lambda s: s['goal'].update(cancel_requested=0), 'goal.cancel_requested'),
    (lambda s: s['goal'].update(recovery_index=5), 'goal.recovery_index'),
    (lambda s: s['goal'].update(recovery_index=-1), 'goal.recovery_index'),
    (lambda s: s['goal'].update(recovery_trigger='STUCK_R'), 'goal.recovery_trigger'),
    (lambda s: s['goal'].update(plan={'x': 1}), 'goal.plan must be a list'),
    (lambda s: s['goal']['plan'].append([1.0, 2.0]), 'goal.plan[3]'),
    (lambda s: s['goal']['plan'].insert(0, [1.0, math.nan, 0.0]), 'goal.plan[0]'),
    (lambda s: s['next_goal'].pop('y'), 'next_goal.y'),
    (lambda s: s['next_goal'].update(id=GOAL.id), 'next_goal.id'),
    (lambda s: s.update(seen_goals='/mfg-2'), 'seen_goals must be a list'),
    (lambda s: s['seen_goals'].append(''), 'seen_goals must be a list'),
    (lambda s: s.update(seen_cancels={}), 'seen_cancels must be a list'),
    (lambda s: s['seen_cancels'].append(['g', -1, 0]), 'seen_cancels[2]'),
    (lambda s: s['seen_cancels'].append(['g', 1]), 'seen_cancels[2]'),
])
def test_a_state_that_does_not_fit_is_refused_naming_the_field(change, field):
    state = copy.deepcopy(good_state())
    change(state)
    with pytest.raises(ValueError, match='move_base state: ' + field.replace('.', r'\.').replace('[', r'\[')):
        parse_state(state, recoveries=4)


def test_not_an_object_is_refused():
    with pytest.raises(ValueError, match='must be an object'):
        parse_state(['goal'], 4)


def test_target_yaw_of_a_quaternion_move_base_would_refuse_is_nan():
    assert target_yaw(yaw_to_quaternion(0.7)) == pytest.approx(0.7)
    assert math.isnan(target_yaw((0.0, 0.0, 0.0, 0.0)))             # zero length
    assert math.isnan(target_yaw((1.0, 0.0, 0.0, 0.0)))             # z axis not vertical


# -- the state machine: recovery sequence continued, timers restarted after a pause -------------------------

class Backend:
    """A robot that gets plans but never a valid velocity command (so the recoveries are reached)."""

    def robot_pose(self):
        return Pose2D(0.0, 0.0, 0.0)

    def check_goal(self, goal):
        pass

    def make_plan(self, start, goal):
        return np.array([[0.0, 0.0, 0.0], [goal.x, goal.y, goal.yaw]])

    def set_plan(self, plan):
        return True

    def compute_velocity(self):
        return None

    def is_goal_reached(self):
        return False

    def sensors_current(self):
        return True


class Instant(Recovery):
    type = 'test/Instant'

    def __init__(self, name):
        self.name = name

    def start(self, now):
        pass

    def step(self, now):
        return StepResult((0.0, 0.0), True)


def core():
    cfg = MoveBaseConfig(controller_frequency=5.0, planner_frequency=0.0, controller_patience=3.0,
                         planner_patience=5.0, max_planning_retries=-1, oscillation_timeout=0.0,
                         oscillation_distance=0.2, recovery_behavior_enabled=True, clearing_rotation_allowed=True,
                         conservative_reset_dist=3.0, shutdown_costmaps=False, make_plan_clear_costmap=True,
                         make_plan_add_unreachable_goal=True)
    return MoveBaseCore(cfg, Backend(), [Instant('first'), Instant('second'), Instant('third')], sync_planner=True)


def first_recovery(c, t0):
    """Cycle until a recovery starts; returns (index, total, name)."""
    for i in range(100):
        result = c.cycle(t0 + 0.2 * i)
        if result.recovery is not None:
            return result.recovery
    raise AssertionError('no recovery started')


@pytest.mark.parametrize('restored, expected', [(None, (0, 3, 'first')), ((1, 'CONTROLLING_R'), (1, 3, 'second'))])
def test_a_goal_taken_over_continues_its_recovery_sequence(restored, expected):
    c = core()
    assert c.new_goal(4.0, 0.0, yaw_to_quaternion(0.0), now=0.0) is None
    if restored is not None:
        c.restore_recovery(*restored)
        assert c.recovery_state() == restored
    assert first_recovery(c, 0.0) == expected


def test_a_goal_taken_over_is_not_checked_again():
    """The instance that accepted the goal checked it; the check reads the global costmap and so waits for an update
    in progress (on the capped robot before the taken-over goal's first command). A new goal is still checked."""
    checked = []

    class Counting(Backend):
        def check_goal(self, goal):
            checked.append((goal.x, goal.y))

    c = core()
    c.backend = Counting()
    assert c.new_goal(4.0, 0.0, yaw_to_quaternion(0.0), now=0.0, checked=True) is None
    assert checked == []
    assert c.new_goal(5.0, 0.0, yaw_to_quaternion(0.0), now=1.0) is None
    assert checked == [(5.0, 0.0)]


def test_restore_recovery_refuses_what_this_instance_does_not_have():
    c = core()
    with pytest.raises(ValueError, match='recovery_index 4'):
        c.restore_recovery(4, 'PLANNING_R')
    with pytest.raises(ValueError, match='trigger'):
        c.restore_recovery(0, 'STUCK_R')


@pytest.mark.parametrize('resume, state', [(False, NavState.CLEARING), (True, NavState.PLANNING)])
def test_a_pause_does_not_count_against_the_patience(resume, state):
    c = core()
    c.new_goal(4.0, 0.0, yaw_to_quaternion(0.0), now=0.0)
    c.cycle(0.0)                   # planned; no valid command yet
    if resume:
        c.resume(100.0)            # the control loop was paused (lease lapsed) until t = 100 s
    c.cycle(100.0)
    assert c.state == state


class Driving(Backend):
    """A robot that follows any plan it is given."""

    def __init__(self):
        self.plans = []

    def set_plan(self, plan):
        self.plans.append(np.asarray(plan))
        return True

    def compute_velocity(self):
        return (0.2, 0.0)


@pytest.mark.parametrize('planner_frequency', [0.0, 1.0])
def test_a_goal_taken_over_with_its_plan_is_controlled_at_once(planner_frequency):
    backend = Driving()
    c = core()
    c.cfg.planner_frequency = planner_frequency
    c.backend, c.sync_planner = backend, False
    assert c.new_goal(4.0, 0.4, yaw_to_quaternion(0.5), now=10.0) is None
    assert c.cycle(10.0).cmd is None                               # without a plan: planning first
    c.restore_plan(np.array(GOAL.plan), now=10.0)
    result = c.cycle(10.01)
    assert result.cmd == (0.2, 0.0) and c.state is NavState.CONTROLLING
    assert np.allclose(backend.plans[-1], GOAL.plan)
    assert not c.planner_due(10.5)                                  # replanned as after a plan of its own
    assert c.planner_due(11.0) == (planner_frequency > 0)
    np.testing.assert_allclose(c.controlled_plan(), GOAL.plan)
    c.reset()
    assert c.controlled_plan() is None
