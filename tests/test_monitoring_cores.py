"""Cores of the monitoring robot without a master: merger, mapcells, store, policies, search, detector,
kestrel lag and parser, report writer. (The grid and the measurement format: tests/test_cnr_maps.py.)"""
import json
import math
import os

import numpy as np
import pytest

from cnr_maps.grid import MapcellGrid
from cnr_params import ConfigError, Section
from cnr_mission.core.report import CellSummary, check_store, path_length, render_png, write_summary
from global_goal_manager.core.policies import CellView, CoverageSweep, LeastRecentlyVisited, make_policy
from kestrel_driver.core.field import TemperatureField
from kestrel_driver.core.parser import ParseError, parse_line
from kestrel_driver.core.sensor import LagCorrector, LaggedSensor
from local_mapcell_manager.core.store import CellBook, MeasurementStore
from merger.core.nearest import NearestMerger
from mfg.core.detector import Detector, DetectorConfig
from mfg.core.search import HotspotSearch


# -- merger ------------------------------------------------------------------------------------
def test_merger_pairs_nearest_not_newest():
    m = NearestMerger(tolerance=0.1, max_wait=0.5)
    m.add_pose(1.00, 'a')
    m.add_pose(1.10, 'b')
    m.add_measurement(1.07, 25.0)            # thesis Figure 4-10: c is closer to b than to a
    m.add_pose(1.20, 'c')                    # the newest pose must not be used
    merged, dropped = m.process(now=1.2)
    assert [(x.pose, x.measurement) for x in merged] == [('b', 25.0)] and not dropped


def test_merger_waits_for_a_later_pose_and_handles_out_of_order():
    m = NearestMerger(tolerance=0.1, max_wait=0.5)
    m.add_pose(2.00, 'p0')
    m.add_measurement(2.05, 1.0)
    assert m.process(now=2.06) == ([], [])   # a closer pose may still come
    m.add_pose(2.20, 'p2')
    m.add_pose(2.06, 'p1')                   # arrives late, out of order
    merged, _ = m.process(now=2.2)
    assert merged[0].pose == 'p1' and merged[0].difference == pytest.approx(0.01)
    assert m.stats.out_of_order_poses == 1


def test_merger_drops_outside_tolerance_and_late_measurements():
    m = NearestMerger(tolerance=0.1, max_wait=0.5)
    m.add_pose(5.0, 'p')
    m.add_measurement(4.5, 1.0)              # no pose within 0.1 s
    m.add_measurement(5.3, 2.0)              # only older poses; decided after max_wait
    merged, dropped = m.process(now=5.4)
    assert merged == [] and [d[1] for d in dropped] == [1.0]
    merged, dropped = m.process(now=5.9)
    assert merged == [] and [d[1] for d in dropped] == [2.0]
    assert m.stats.dropped_no_pose == 2 and m.stats.merged == 0


# -- mapcells and store --------------------------------------------------------------------------
def corridor_grid():
    return MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=11, rows=2)


def test_statistics_visits_and_store_reload(tmp_path):
    g = corridor_grid()
    path = str(tmp_path / 'store.tsv')
    store, book = MeasurementStore(path), CellBook(g)
    values = [(0.5, 0.5, 22.0), (0.6, 0.5, 24.0), (1.5, 0.5, 30.0), (0.5, 0.5, 23.0)]
    for i, (x, y, t) in enumerate(values, 1):
        m = book.new_measurement(float(i), x, y, t, float(i))
        assert m.number == i and (m.row, m.col) == g.row_col(g.index_of(x, y))
        store.append(m)
        book.add(m)
    assert book.new_measurement(5.0, 11.5, 0.5, 22.0, 5.0) is None          # outside the grid
    s = book.states[g.index_of(0.5, 0.5)]
    assert s.n == 3 and s.mean == pytest.approx(23.0) and s.std == pytest.approx(1.0)
    assert s.visit_count == 2 and s.last_visit == 4.0 and s.max == 24.0
    with open(path, 'a') as f:                              # a crash in the middle of a line
        f.write('5\t5.0\t0.5')
    warnings = []
    store2 = MeasurementStore(path, warnings.append)
    reloaded = CellBook(g)
    for m in store2.load(g):
        reloaded.add(m)
    assert reloaded.count == 4 and warnings
    size = os.path.getsize(path)
    store2.append(reloaded.new_measurement(5.0, 0.5, 0.5, 21.0, 5.0))
    assert os.path.getsize(path) > size                     # nothing truncated
    assert [m.number for m in MeasurementStore(path).load(g)] == [1, 2, 3, 4, 5]


# -- global goal policies -------------------------------------------------------------------------
def grid_views(times, cols=5, rows=5):
    return [CellView(r * cols + c, r, c, c + 0.5, r + 0.5, times.get((c, r), 0.0)) for r in range(rows)
            for c in range(cols)]


def test_least_recently_visited_thesis_5x5_example():
    # thesis Figure 4-7 / paper Fig. 7, with the timestamp method: the robot is at (0, 4); (4, 0) was visited
    # longest ago, then (0, 0), then (0, 1).
    times = {(c, r): 50.0 + r * 5 + c for c in range(5) for r in range(5)}
    times.update({(4, 0): 1.0, (0, 0): 2.0, (0, 1): 3.0})
    policy = LeastRecentlyVisited()
    index = lambda c, r: r * 5 + c
    first = policy.next_cell(grid_views(times), index(0, 4), (0.5, 4.5))
    assert first == index(4, 0)
    for k, cell in enumerate([(1, 3), (2, 2), (3, 1), (4, 0)]):   # drive there; timestamps updated
        times[cell] = 100.0 + k
    second = policy.next_cell(grid_views(times), index(4, 0), (4.5, 0.5))
    assert second == index(0, 0)
    for k, cell in enumerate([(3, 0), (2, 0), (1, 0), (0, 0)]):
        times[cell] = 200.0 + k
    assert policy.next_cell(grid_views(times), index(0, 0), (0.5, 0.5)) == index(0, 1)


def test_lrv_prefers_never_visited_far_cells_and_never_the_robot_cell():
    views = grid_views({}, cols=11, rows=2)
    policy = LeastRecentlyVisited()
    assert policy.next_cell(views, 0, (0.5, 0.5)) == 21            # the far end of the corridor
    assert policy.next_cell([views[0]], 0, (0.5, 0.5)) is None


def test_coverage_sweep_is_a_z_patrol_and_unknown_policy_fails():
    sweep = CoverageSweep()
    views = grid_views({}, cols=11, rows=2)
    assert [sweep.next_cell(views, None, (0, 0)) for _ in range(5)] == [0, 10, 21, 11, 0]
    with pytest.raises(ConfigError) as err:
        make_policy('random_walk', 'scenario.yaml', 'global_goal_manager.policy')
    assert 'random_walk' in str(err.value) and 'least_recently_visited' in str(err.value)


# -- hotspot search ---------------------------------------------------------------------------------
def five_by_five(connectivity=8):
    g = MapcellGrid(0.0, 0.0, 1.0, 5, 5)
    return g, (lambda i: g.neighbours(i, connectivity))


def field_mean(g, index, hot=(3.2, 2.4)):
    c = g.cell(index)
    return 30.0 - 3.0 * math.hypot(c.center_x - hot[0], c.center_y - hot[1])


@pytest.mark.parametrize('connectivity', [8, 4])
def test_search_figure_4_8(connectivity):
    g, nb = five_by_five(connectivity)
    ic, previous = g.index_at(2, 2), g.index_at(3, 2)          # found in (2)(2) coming from (2)(3)
    s = HotspotSearch(nb, ic, field_mean(g, ic), previous, {previous: field_mean(g, previous)})
    assert previous in s.checked and previous not in s.unchecked
    visited = 0
    while not s.done:
        t = s.next_target()
        s.report(t, field_mean(g, t))
        visited += 1
        assert visited < 25
    assert s.hotspot == g.index_at(2, 3)                      # mapcell(3)(2): x = 3, y = 2
    assert s.ic_history[0] == ic and len(s.ic_history) == 2


def test_search_unreachable_neighbour_is_checked_and_search_goes_on():
    g, nb = five_by_five()
    ic = g.index_at(2, 2)
    s = HotspotSearch(nb, ic, field_mean(g, ic))
    blocked = g.index_at(3, 4)                                # a neighbour of the final IC only
    while not s.done:
        t = s.next_target()
        if t == blocked:
            s.report(t, float('nan'))
        else:
            s.report(t, field_mean(g, t))
    assert s.hotspot == g.index_at(2, 3)
    assert any(h.outcome == 'unreachable' for h in s.history)


# -- detector ---------------------------------------------------------------------------------------
def test_detector_modes_and_nan_threshold():
    d = Detector(DetectorConfig(mode='ambient', ambient=22.0, delta=2.0, z=3.0, min_samples=20))
    assert not d.observe(23.9) and d.observe(24.1)
    s = Detector(DetectorConfig(mode='statistics', ambient=22.0, delta=1.0, z=3.0, min_samples=10))
    rng = np.random.default_rng(0)
    assert not any(s.observe(22.0 + rng.normal(0, 0.1)) for _ in range(50))
    assert s.observe(25.0)
    with pytest.raises(ConfigError):
        Detector(DetectorConfig(mode='ambient', ambient=22.0, delta=float('nan'), z=3.0, min_samples=20))
    good = {'mode': 'ambient', 'ambient': 22.0, 'delta': 2.0, 'z': 3.0, 'min_samples': 20}
    with pytest.raises(ConfigError, match='threshold.delta: must be finite'):
        DetectorConfig.from_section(Section(dict(good, delta=float('nan')), 'scenario.yaml', 'threshold'))
    for key in good:                                          # no defaults in code: each field is required
        with pytest.raises(ConfigError, match=f'scenario.yaml: threshold.{key}: missing'):
            DetectorConfig.from_section(Section({k: v for k, v in good.items() if k != key}, 'scenario.yaml',
                                                'threshold'))


# -- kestrel -----------------------------------------------------------------------------------------
def test_lag_step_response_is_exact():
    s = LaggedSensor(time_constant=6.0, initial=20.0)
    s.update(20.0, 0.0)
    for t in np.arange(0.1, 12.01, 0.1):
        v = s.update(30.0, float(t))
    assert v == pytest.approx(30.0 - 10.0 * math.exp(-12.0 / 6.0), abs=1e-9)


def test_lag_correction_reduces_error_through_a_heat_source():
    field = TemperatureField.from_section(Section({'ambient': 22.0, 'sources': [
        {'name': 'h', 'x': 5.0, 'y': 0.0, 'peak': 10.0, 'radius': 0.8, 'start': 0.0, 'ramp': 0.0}]}, 'f.yaml'))
    tau = 6.0
    sensor, corr = LaggedSensor(tau), LagCorrector(tau, window=5)
    rng = np.random.default_rng(1)
    raw_err, cor_err = [], []
    t = 0.0
    while t < 20.0:                                           # 0.5 m/s past the heater
        for k in range(15):                                   # 50 Hz poses, 3.33 Hz readings
            t += 0.02
            air = field.at(0.5 * t, 0.3, t)
            sensor.update(air, t)
        reading = sensor.value + rng.normal(0, 0.05)
        corrected = corr.update(reading, t)
        if t > 3.0:
            raw_err.append(reading - air)
            cor_err.append(corrected - air)
    rms = lambda e: math.sqrt(sum(x * x for x in e) / len(e))
    assert rms(cor_err) < 0.6 * rms(raw_err)


def test_field_validation():
    good = {'name': 'h', 'x': 0, 'y': 0, 'peak': 5, 'radius': 1.0, 'start': 0.0, 'ramp': 0.0}
    with pytest.raises(ConfigError) as err:
        TemperatureField.from_section(Section({'ambient': 22.0, 'sources': [dict(good, radius=0)]}, 'scenario.yaml'))
    assert 'sources[0].radius' in str(err.value)
    with pytest.raises(ConfigError, match=r"sources\[0\].peak: expected a number, got 'hot'"):
        TemperatureField.from_section(Section({'ambient': 22.0, 'sources': [dict(good, peak='hot')]}, 's.yaml'))
    for key in good:
        with pytest.raises(ConfigError, match=rf'sources\[0\].{key}: missing'):
            TemperatureField.from_section(Section({'ambient': 22.0, 'sources': [
                {k: v for k, v in good.items() if k != key}]}, 'scenario.yaml'))


@pytest.mark.parametrize('line, value', [('23.4', 23.4), ('T,23.4\r\n', 23.4), ('TEMP,74.12,F', 23.4),
                                         ('$KES,23.4,C', 23.4)])
def test_parser_accepts(line, value):
    assert parse_line(line) == pytest.approx(value, abs=0.01)


@pytest.mark.parametrize('line', ['', 'hello', 'T,', '23.4,K', '$KES,23.4,C*00', 'nan', '900'])
def test_parser_rejects_garbage(line):
    with pytest.raises(ParseError):
        parse_line(line)


# -- report ------------------------------------------------------------------------------------------
def test_report_files(tmp_path):
    write_summary(str(tmp_path / 's.json'), {'found': True, 'x': float('nan')})
    assert json.load(open(tmp_path / 's.json')) == {'found': True, 'x': None}
    cells = [CellSummary(i, 0, i, i, i + 1, 0, 1, 22.0 + i if i != 2 else float('nan'), 3) for i in range(4)]
    render_png(str(tmp_path / 'c.png'), cells, [(0.5, 0.5), (3.5, 0.5)], 3, 'test')
    assert (tmp_path / 'c.png').stat().st_size > 1000
    assert path_length([(0, 0), (3, 4)]) == 5.0


# -- mfg's local fallback goals and cnr_runtime.call_with_timeout ------------------------------------
def test_local_goals_pick_the_least_recently_measured_cell_not_the_robots():
    from cnr_maps.grid import MapcellGrid
    from mfg.core.fallback import LocalGoals
    grid = MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=3, rows=1)
    goals = LocalGoals()
    assert goals.next_cell(grid, (0.5, -0.5)) == 2          # never-visited first, farthest on a tie
    goals.visited(2, 10.0)
    goals.visited(1, 5.0)
    goals.visited(1, 4.0)                                    # an older time does not move the last visit back
    assert goals.last_visit[1] == 5.0
    assert goals.next_cell(grid, (2.5, -0.5)) == 0           # cell 0 never measured
    goals.visited(0, 20.0)
    assert goals.next_cell(grid, (2.5, -0.5)) == 1           # the oldest of 0 (20 s) and 1 (5 s); 2 is the robot's


def test_call_with_timeout_returns_results_errors_and_gives_up_in_time():
    import threading
    import time
    from cnr_runtime import call_with_timeout
    assert call_with_timeout(lambda a, b: a + b, 1.0, 2, 3) == (True, 5)
    ok, err = call_with_timeout(lambda: 1 / 0, 1.0)
    assert not ok and isinstance(err, ZeroDivisionError)
    release = threading.Event()
    t0 = time.monotonic()
    ok, err = call_with_timeout(release.wait, 0.2)
    took = time.monotonic() - t0
    release.set()
    assert not ok and isinstance(err, TimeoutError)
    assert took < 5.0                                        # gave up instead of waiting for the call


# -- mfg activity (the paper's dead-zone idle time) ------------------------------------------------
def test_activity_tracker_gaps_and_waits():
    from mfg.core.activity import ActivityTracker
    a = ActivityTracker()
    assert a.report(5.0).longest_idle == 0.0          # nothing received yet: no gap to speak of
    for t in (10.0, 10.33, 10.66):
        a.input(t)
    assert a.report(10.7).longest_input_gap == pytest.approx(0.33, abs=1e-9)
    a.input(14.66)                                     # a 4 s outage
    a.waited(0.2)
    a.waited(0.5)
    r = a.report(14.7)
    assert r.longest_input_gap == pytest.approx(4.0)
    assert (r.goal_waits, r.goal_wait_total, r.goal_wait_longest) == (2, pytest.approx(0.7), 0.5)
    assert r.longest_idle == pytest.approx(4.0)
    assert a.report(20.66).longest_input_gap == pytest.approx(6.0)      # an open gap counts up to now


def test_store_check_compares_only_what_both_saw_and_finds_losses_and_duplicates():
    published = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    # the store connected after the first and was read before the last: nothing lost
    c = check_store(published, [2.0, 3.0, 4.0, 5.0])
    assert (c['missing_count'], c['duplicates'], c['unseen'], c['published_before_first'], c['in_flight']) == \
        (0, 0, 0, 1, 1)
    assert c['published_since_first'] == c['stored_in_window'] == 4
    # the monitor connected to a new merger after the store did, and the store was read after the monitor's copy
    c = check_store([2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0, 5.0])
    assert c['missing_count'] == 0 and c['unseen'] == 0 and c['published_since_first'] == 3, c
    # one lost in the middle, one stored twice, one the monitor never saw
    c = check_store(published, [1.0, 2.0, 2.0, 3.5, 4.0, 6.0])
    assert (c['missing_count'], c['missing'], c['duplicates'], c['unseen']) == (2, [3.0, 5.0], 1, 1), c
    assert check_store(published, [])['published_before_first'] == 6
    # two measurements sharing a stamp, both stored: neither lost nor a duplicate
    c = check_store([1.0, 2.0, 2.0, 3.0], [1.0, 2.0, 2.0, 3.0])
    assert (c['missing_count'], c['duplicates'], c['shared_stamps']) == (0, 0, 1), c
    assert check_store([1.0, 2.0, 2.0, 3.0], [1.0, 2.0, 3.0])['missing'] == [2.0]
