"""mfg's migration state without ROS: the detector's threshold statistics, the hotspot search, the local goals'
visit times, the activity counters and the whole node state (core/memory.py) survive a hand-over (through the
migration codec's JSON): a restored object behaves exactly as the original on the same further inputs, and a
state that does not fit is refused with a ValueError naming the field, changing nothing."""
import copy
import json
import math

import numpy as np
import pytest

from cnr_maps.grid import MapcellGrid
from mfg.core.activity import ActivityTracker
from mfg.core.detector import Detector, DetectorConfig
from mfg.core.fallback import LocalGoals
from mfg.core.memory import MEASUREMENTS_HANDED_OVER, MEASUREMENTS_KEPT, Goal, Memory
from mfg.core.search import HotspotSearch

AMBIENT = DetectorConfig(mode='ambient', ambient=22.0, delta=2.0, z=3.0, min_samples=20)
STATISTICS = DetectorConfig(mode='statistics', ambient=22.0, delta=1.0, z=3.0, min_samples=10)


def handed_over(state):
    """What the successor receives: the migration codec's compressed JSON, decoded."""
    from migration_manager.core import state as codec
    return codec.decode('mfg', codec.encode('mfg', state))


# -- detector ---------------------------------------------------------------------------------------
@pytest.mark.parametrize('cfg', [AMBIENT, STATISTICS], ids=['ambient', 'statistics'])
def test_detector_restored_judges_like_the_original(cfg):
    rng = np.random.default_rng(1)
    values = list(22.0 + rng.normal(0, 0.3, 200)) + [25.0, 22.1, 26.0] + list(22.0 + rng.normal(0, 0.3, 50))
    original = Detector(cfg)
    for v in values[:100]:
        original.observe(v)
    clone = Detector(cfg)
    clone.restore(handed_over(original.state()))
    assert clone.state() == original.state()
    assert [clone.observe(v) for v in values[100:]] == [original.observe(v) for v in values[100:]]
    assert clone.state() == original.state()
    if cfg.mode == 'statistics':
        fresh = Detector(cfg)                          # the statistics matter: a fresh detector judges otherwise
        assert not fresh.observe(25.0) and clone.observe(25.0)


@pytest.mark.parametrize('state, field', [
    ({'mean': 22.0, 'm2': 1.0}, 'detector.n: missing'),
    ({'n': -1, 'mean': 22.0, 'm2': 1.0}, 'detector.n: must be >= 0'),
    ({'n': 2.5, 'mean': 22.0, 'm2': 1.0}, 'detector.n: expected an integer'),
    ({'n': 3, 'mean': 'warm', 'm2': 1.0}, 'detector.mean: expected a number'),
    ({'n': 3, 'mean': 22.0, 'm2': float('nan')}, 'detector.m2: must be finite'),
    ({'n': 3, 'mean': 22.0, 'm2': -1.0}, 'detector.m2: must be >= 0'),
    ([3, 22.0, 1.0], 'detector: expected an object'),
])
def test_detector_refuses_a_bad_state_and_keeps_its_own(state, field):
    d = Detector(STATISTICS)
    d.observe(22.0)
    before = d.state()
    with pytest.raises(ValueError, match=f'mfg state: {field}'):
        d.restore(state)
    assert d.state() == before


# -- hotspot search ---------------------------------------------------------------------------------
def grid5(connectivity):
    g = MapcellGrid(0.0, 0.0, 1.0, 5, 5)
    return g, (lambda i: g.neighbours(i, connectivity))


def field_mean(g, index, hot=(3.2, 2.4)):
    c = g.cell(index)
    return 30.0 - 3.0 * math.hypot(c.center_x - hot[0], c.center_y - hot[1])


def run_to_end(s, g, blocked=()):
    """Targets and outcomes until the search is done (a blocked cell cannot be measured)."""
    steps = []
    while not s.done:
        t = s.next_target(lambda i: abs(i - 12))
        step = s.report(t, math.nan if t in blocked else field_mean(g, t))
        steps.append((t, step.outcome, s.ic))
        assert len(steps) < 30
    return steps


@pytest.mark.parametrize('connectivity', [4, 8])
def test_search_restored_at_every_step_goes_on_exactly_as_the_original(connectivity):
    g, nb = grid5(connectivity)
    ic, previous = g.index_at(2, 2), g.index_at(3, 2)
    blocked = {g.index_at(3, 4)}

    def start():
        return HotspotSearch(nb, ic, field_mean(g, ic), previous, {previous: field_mean(g, previous)})
    whole = run_to_end(start(), g, blocked)
    assert any(o == 'unreachable' for _, o, _ in whole) or connectivity == 4
    for k in range(len(whole) + 1):
        original = start()
        for t, _, _ in whole[:k]:
            original.report(t, math.nan if t in blocked else field_mean(g, t))
        clone = HotspotSearch.from_state(nb, handed_over(original.state()), len(g))
        assert json.dumps(clone.state()) == json.dumps(original.state())    # NaN means of unreachable cells too
        assert clone.done == original.done and clone.hotspot == original.hotspot
        assert run_to_end(clone, g, blocked) == whole[k:]
        assert clone.hotspot == g.index_at(2, 3)


def test_search_refuses_a_state_that_does_not_fit():
    g, nb = grid5(4)
    s = HotspotSearch(nb, 12, 27.0, 17, {17: 25.0})
    good = s.state()

    def bad(**change):
        return dict(copy.deepcopy(good), **change)
    cases = [
        (bad(ic=99), 'search.ic: cell 99 is outside the grid'),
        (bad(ic='12'), 'search.ic: expected a cell index'),
        (bad(ic_mean=None), 'search.ic_mean: expected a number'),
        (bad(unchecked=[0]), r'search.unchecked: cells \[0\] are not neighbours of the investigation cell 12'),
        (bad(checked=[7]), r'search.unchecked: cells \[7\] are also checked'),
        (bad(history=[[7, 25.0, 'lukewarm']]), 'search.history: unknown outcome'),
        (bad(history=[[7, 25.0]]), 'search.history: item 0: expected a list of 3 values'),
        (bad(known=[[7, float('nan')]]), 'search.known: must be finite'),
        (bad(ic_history=[11]), 'search.ic_history: must end with the investigation cell 12'),
        ({k: v for k, v in good.items() if k != 'previous'}, 'search.previous: missing'),
        ({k: v for k, v in good.items() if k != 'unchecked'}, 'search.unchecked: missing'),
    ]
    for state, message in cases:
        with pytest.raises(ValueError, match=f'mfg state: {message}'):
            HotspotSearch.from_state(nb, state, len(g))
    # a state made on a larger grid: its IC's neighbours are not this grid's
    big = MapcellGrid(0.0, 0.0, 1.0, 7, 7)
    other = HotspotSearch(lambda i: big.neighbours(i, 4), 8, 27.0).state()
    with pytest.raises(ValueError, match='not neighbours of the investigation cell 8'):
        HotspotSearch.from_state(nb, other, len(g))


# -- local goals and activity -----------------------------------------------------------------------
def test_local_goals_and_activity_round_trip_and_bad_states():
    grid = MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=4, rows=2)
    goals = LocalGoals()
    for cell, t in ((0, 1.0), (1, 2.0), (5, 3.0), (2, 4.0)):
        goals.visited(cell, t)
    clone = LocalGoals()
    clone.restore(handed_over(goals.state()), len(grid))
    assert clone.last_visit == goals.last_visit
    for robot in ((0.5, -0.5), (3.5, 0.5), (1.5, 0.5)):
        assert clone.next_cell(grid, robot) == goals.next_cell(grid, robot)
        cell = goals.next_cell(grid, robot)
        goals.visited(cell, 10.0 + cell)
        clone.visited(cell, 10.0 + cell)
    with pytest.raises(ValueError, match='mfg state: local_goals.last_visit: cell 8 is outside the grid'):
        clone.restore({'last_visit': [[8, 1.0]]}, len(grid))
    with pytest.raises(ValueError, match='mfg state: local_goals.last_visit: missing'):
        clone.restore({}, len(grid))

    a = ActivityTracker()
    for t in (1.0, 1.3, 5.0):
        a.input(t)
    a.waited(0.4)
    b = ActivityTracker()
    b.restore(handed_over(a.state()))
    for t in (5.3, 9.5):
        a.input(t)
        b.input(t)
    assert b.report(10.0) == a.report(10.0)
    with pytest.raises(ValueError, match='mfg state: activity.goal_waits: expected an integer'):
        b.restore(dict(a.state(), goal_waits='1'))
    fresh = ActivityTracker()
    fresh.restore(ActivityTracker().state())            # nothing received yet: last_input is null
    assert fresh.report(3.0).longest_input_gap == 0.0


# -- the node's state (core/memory.py) --------------------------------------------------------------
CORRIDOR = MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=11, rows=2)


def memory(cfg=AMBIENT):
    m = Memory(cfg, 4, 2)
    m.grid = CORRIDOR
    return m


def patrol_inputs(n, t0=0.0, hot_from=None):
    """Measurements along row 0 of the corridor at 3 Hz; from ``hot_from`` on, 4 degC above ambient."""
    out = []
    for i in range(n):
        t = t0 + i / 3.0
        cell = int(t / 4.0) % 11                            # a cell every 4 s
        out.append((t, cell, 22.0 + 0.1 * math.sin(i) + (4.0 if hot_from is not None and t >= hot_from else 0.0)))
    return out


def busy_memory():
    """A memory in the middle of a search, with a goal being driven to."""
    m = memory(STATISTICS)
    m.mode = 'PATROL'
    triggers = [m.observe(*x) for x in patrol_inputs(120, hot_from=30.0)]
    trigger = next(t for t in triggers if t is not None)
    assert m.trigger == trigger and trigger.previous is not None
    m.mode = 'SEARCH'
    m.search = HotspotSearch(m.neighbours, trigger.cell, 26.0, trigger.previous, {trigger.previous: 22.0})
    target = m.search.next_target()
    m.goal = Goal(CORRIDOR.cell(target).center_x, CORRIDOR.cell(target).center_y, 1.5, target, False, 'check', 40.0)
    m.hotspots.append(20)
    m.activity.input(40.0)
    m.activity.waited(0.2)
    return m


def test_memory_round_trip_then_the_same_inputs_give_the_same_state():
    m = busy_memory()
    state = m.to_state()
    clone = memory(STATISTICS)
    assert clone.restore(handed_over(state)) == 0
    assert json.dumps(clone.to_state()) == json.dumps(state)
    assert clone.goal == m.goal and clone.trigger == m.trigger
    later = patrol_inputs(60, t0=41.0, hot_from=0.0)
    assert [clone.observe(*x) for x in later] == [m.observe(*x) for x in later]
    assert json.dumps(clone.to_state()) == json.dumps(m.to_state())
    # and the search goes on identically
    for s in (m.search, clone.search):
        t = s.next_target()
        s.report(t, 23.0)
    assert clone.search.state() == m.search.state()


def test_memory_hands_over_bounded_measurements_and_trail():
    m = memory()
    m.mode = 'PATROL'
    for x in patrol_inputs(2000):
        m.observe(*x)
    state = m.to_state()
    assert len(state['measurements']) == MEASUREMENTS_HANDED_OVER
    assert state['measurements'][-1] == list(m.measurements[-1])
    assert len(state['cell_trail']) <= 100 and state['cell_trail'][-1] == m.cell_trail[-1]


def test_a_late_measurement_is_kept_in_stamp_order_and_the_state_is_taken_over():
    """A store that recovered measurements from the merger after a failover publishes them after newer ones: the
    memory keeps stamp order, so its state is one another instance accepts (it refused "stamps must not
    decrease", and the module was left with no active instance)."""
    m = memory()
    m.mode = 'PATROL'
    inputs = patrol_inputs(40)
    for x in inputs[:20] + inputs[25:] + inputs[20:25]:        # five arrive late
        m.observe(*x)
    assert list(m.measurements) == inputs
    assert memory().restore(handed_over(m.to_state())) == 0
    full = memory()
    for x in patrol_inputs(MEASUREMENTS_KEPT + 10)[10:]:
        full.observe(*x)
    oldest = full.measurements[0]
    full.observe(oldest[0] - 1.0, oldest[1], 20.0)                # older than all kept: dropped
    assert full.measurements[0] == oldest and len(full.measurements) == MEASUREMENTS_KEPT
    full.observe(full.measurements[5][0] + 1e-3, oldest[1], 20.0)
    assert len(full.measurements) == MEASUREMENTS_KEPT
    assert all(a[0] <= b[0] for a, b in zip(full.measurements, list(full.measurements)[1:]))


def test_a_standby_replays_what_arrived_after_the_state_and_may_trigger_from_it():
    inputs = patrol_inputs(150, hot_from=45.0)
    first_hot = next(i for i, x in enumerate(inputs) if x[2] > 24.0)
    active, standby = memory(), memory()
    active.mode = 'PATROL'
    for x in inputs[:first_hot - 5]:                       # the active instance is frozen before the heat ...
        active.observe(*x)
        standby.observe(*x)
    state = active.to_state()
    for x in inputs[first_hot - 5:first_hot + 3]:          # ... the standby keeps following its inputs
        standby.observe(*x)
    assert standby.trigger is None                         # a standby never triggers (it is IDLE)
    assert standby.restore(handed_over(state)) == 8        # the 8 newer measurements replayed
    assert standby.mode == 'PATROL'
    assert standby.trigger is not None and standby.trigger.t == inputs[first_hot][0]
    assert list(standby.measurements) == inputs[:first_hot + 3]
    assert standby.local_goals.last_visit[inputs[first_hot + 2][1]] == inputs[first_hot + 2][0]


def test_memory_refuses_a_state_that_does_not_fit_and_changes_nothing():
    m = busy_memory()
    good = m.to_state()
    target = memory(STATISTICS)
    for x in patrol_inputs(10):
        target.observe(*x)
    before = json.dumps(target.to_state())

    def bad(**change):
        return dict(copy.deepcopy(good), **change)
    goal = good['goal']
    cases = [
        (bad(mode='SLEEPING'), 'mode: unknown value'),
        ({k: v for k, v in good.items() if k != 'detector'}, 'detector: missing'),
        (bad(detector={'n': 1, 'mean': 22.0}), 'detector.m2: missing'),
        (bad(grid=dict(good['grid'], cols=12)), 'grid: .* differs from this instance'),
        (bad(trigger=dict(good['trigger'], cell=22)), 'trigger.cell: cell 22 is outside the grid'),
        (bad(hotspots=[3, 'x']), 'hotspots: expected a cell index'),
        (bad(measurements=[[1.0, 3]]), 'measurements: item 0: expected a list of 3 values'),
        (bad(measurements=[[2.0, 3, 22.0], [1.0, 3, 22.0]]), 'measurements: stamps must not decrease'),
        (bad(goal=dict(goal, kind='wander')), 'goal.kind: unknown value'),
        (bad(goal=dict(goal, interruptible='no')), 'goal.interruptible: expected true or false'),
        (bad(goal={k: v for k, v in goal.items() if k != 'x'}), 'goal.x: missing'),
        (bad(search=None), 'goal: a goal of kind check without a search'),
        (bad(trigger=None), 'search: a search without a trigger'),
        (bad(search=dict(good['search'], unchecked=[0])), 'search.unchecked: .* not neighbours'),
        (bad(local_goals={'last_visit': [[1, 'noon']]}), 'local_goals.last_visit: expected a number'),
        ('not a state', 'mfg state: expected an object'),
    ]
    for state, message in cases:
        with pytest.raises(ValueError, match=message):
            target.restore(state)
        assert json.dumps(target.to_state()) == before, message
    # a state without a grid but with a search, restored where no grid is known either
    blind = Memory(STATISTICS, 4, 2)
    with pytest.raises(ValueError, match='search: a search without a grid'):
        blind.restore(bad(grid=None))
    blind.restore(good)                                    # the state's grid is adopted
    assert blind.grid == CORRIDOR
