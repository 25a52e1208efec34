"""The learned decision's measures (cnr_benchmarks.core.decision_measures) and campaign_summary.json written by the
campaign's analysis, on small synthetic tables whose answers are known. ROS-free: no master."""
import ast
import csv
import dataclasses
import json
import math
import os
import random

import pytest

from cnr_benchmarks.core import campaign
from cnr_benchmarks.core import decision_measures as dm
from network_monitor.core.decision import ColdStartRule, DecisionSettings, Exploration, Normalisation
from network_monitor.core.evaluation import (ABORTED, COMPLETED, OFFLOAD, ONLOAD, TIMED_OUT, ControlValues, Outcome,
                                             write_control_values)
from network_monitor.core.training import HEADER, Row, format_row

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EITHER = campaign.EITHER
# a control whose single-run value sd is 0.5 * hypot(0.01, 0.01) = 0.00707: two runs' tolerance 0.02
CONTROL = ControlValues('latency_task', 30.0, 0.3, 0.003, 0.00003, 20, '2026-11-28', 'test')
SETTINGS = DecisionSettings(k=5, normalisation=Normalisation(rtt_max=0.4, r_bw_min=1.0, r_bw_max=100.0),
                            cold_start=ColdStartRule(rtt=0.1, r_bw=10.0),
                            exploration=Exploration(rate=0.3, max_rtt=0.2, seed=0))


def run(value, status=COMPLETED):
    """An outcome whose Eq. 4-5 value under CONTROL is ``value`` (T and B both at ``value`` times the control)."""
    return Outcome(30.0 * value, 0.003 * value, status)


def trial(task, cid, c_l, r_bw, offload, onload):
    return dm.Trial(task, cid, 1000.0 * c_l, c_l, r_bw, tuple(offload), tuple(onload))


def test_the_module_never_imports_rospy():
    path = os.path.join(WS, 'src', 'cnr_benchmarks', 'src', 'cnr_benchmarks', 'core', 'decision_measures.py')
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read())
    imported = {a.name.split('.')[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split('.')[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert 'rospy' not in imported


# ---------------------------------------------------------------- trials from the rows
def _row(cid, placement, status, value, task=None, placed='1', c_l=0.02, r_bw=50.0):
    r = dict(id=f'{cid}-{placement}', condition=cid, decision=placement, mission_status=status,
             t_task=str(30.0 * value), b_task=str(0.003 * value), rtt_ms='20', c_l=str(c_l), r_bw=str(r_bw),
             placed=placed)
    if task:
        r['task'] = task
    return r


def test_trials_keep_every_repeat_per_task_and_leave_out_unmade_placements():
    rows = [_row('c1', ONLOAD, COMPLETED, 1.0, c_l=0.03, r_bw=7.0), _row('c1', OFFLOAD, COMPLETED, 0.9),
            _row('c1', ONLOAD, COMPLETED, 1.1), _row('c1', OFFLOAD, TIMED_OUT, 1.6),
            _row('c1', ONLOAD, COMPLETED, 1.0, task='patrol'), _row('c1', OFFLOAD, COMPLETED, 0.8, task='patrol'),
            _row('c2', ONLOAD, COMPLETED, 1.0), _row('c2', OFFLOAD, ABORTED, 0.1, placed='0'),   # not made: out
            _row('c3', ONLOAD, COMPLETED, 1.0)]                                                 # one placement: out
    ts = dm.trials(rows, 'corridor_round_trip')
    assert [(t.task, t.condition) for t in ts] == [('corridor_round_trip', 'c1'), ('patrol', 'c1')]
    assert (ts[0].c_l, ts[0].r_bw) == (0.03, 7.0)              # the first run's profile
    assert [o.mission_status for o in ts[0].offload] == [COMPLETED, TIMED_OUT] and len(ts[0].onload) == 2
    assert dm.tasks_of(ts) == ['corridor_round_trip', 'patrol']
    train, held = dm.split(ts + [dm.Trial('patrol', f'x{i}', 0, 0, 0, (), ()) for i in range(3)], 0.5)
    assert [(t.task, t.condition) for t in held] == [('patrol', 'x1'), ('patrol', 'x2')]   # per task: 0 of 1, 2 of 4
    assert len(train) == 3
    five = [dm.Trial('x', f'x{i}', 0, 0, 0, (), ()) for i in range(5)]
    assert [t.condition for t in dm.split(five, 0.3)[1]] == ['x3', 'x4']       # round(1.5): as the learning curve


def test_a_priori_rules_on_the_profile():
    rules = dm.a_priori_rules(SETTINGS)
    assert set(rules) == {dm.ALWAYS_ONLOAD, dm.ALWAYS_OFFLOAD, dm.COLD_START_RULE, dm.RTT_RULE}
    profiles = [(0.04, 5.0), (0.06, 50.0), (0.09, 11.0), (0.09, 9.0), (0.11, 50.0), (math.nan, 50.0)]
    ts = [trial('t', 'c', c_l, r_bw, [], []) for c_l, r_bw in profiles]
    assert [rules[dm.RTT_RULE](t) for t in ts] == [OFFLOAD, ONLOAD, ONLOAD, ONLOAD, ONLOAD, ONLOAD]
    # config/decision.yaml's cold start: offload iff C_l < 0.1 s and R_bw > 10
    assert [rules[dm.COLD_START_RULE](t) for t in ts] == [ONLOAD, OFFLOAD, OFFLOAD, ONLOAD, ONLOAD, ONLOAD]
    assert {rules[dm.ALWAYS_ONLOAD](t) for t in ts} == {ONLOAD}
    assert {rules[dm.ALWAYS_OFFLOAD](t) for t in ts} == {OFFLOAD}


# ---------------------------------------------------------------- the noise-aware oracle
def test_oracle_from_repeats_uses_their_spread():
    tight = trial('t', 'a', 0.02, 50, [run(0.978), run(0.988)], [run(0.995), run(1.005)])
    # 0.017 apart; each placement's sd 0.00707, so twice the se of the difference of two means of 2: 0.0141
    assert dm.trial_oracle(tight, CONTROL) == OFFLOAD
    loose = trial('t', 'b', 0.02, 50, [run(0.8), run(1.1)], [run(1.0), run(1.01)])
    assert dm.trial_oracle(loose, CONTROL) == EITHER                # 0.055 apart, within the offload repeats' 0.21
    wide = trial('t', 'c', 0.02, 50, [run(0.7), run(1.1)], [run(1.0), run(1.02)])
    # 0.11 apart; the offload repeats' sd 0.283: 2 * sqrt(0.283^2 / 2 + 0.0141^2 / 2) = 0.40 > 0.09
    assert dm.trial_oracle(wide, CONTROL) == EITHER
    assert dm.trial_oracle(wide, CONTROL, noise_aware=False) == OFFLOAD     # strict: always a winner


def test_oracle_with_one_run_per_placement_is_the_campaigns():
    tol = campaign.noise_tolerance(CONTROL)
    assert dm.single_run_sd(CONTROL) == pytest.approx(0.5 * math.hypot(0.01, 0.01))
    cases = [(run(0.97), run(1.0)), (run(0.99), run(1.0)), (run(1.03), run(1.0)), (run(0.5, ABORTED), run(1.0)),
             (run(1.0), run(1.5, TIMED_OUT)), (run(0.5, ABORTED), run(1.5, TIMED_OUT)), (run(1.0), run(1.0))]
    got = [dm.trial_oracle(trial('t', 'c', 0.02, 50, [off], [on]), CONTROL) for off, on in cases]
    assert got == [OFFLOAD, EITHER, ONLOAD, ONLOAD, OFFLOAD, ONLOAD, EITHER]
    pairs = [campaign.Pair('c', 20, 20, 0, 0.02, 50, OFFLOAD, 'knn', off, on, {}, {}) for off, on in cases]
    assert got == [campaign.oracle(p, CONTROL, tol) for p in pairs]
    assert [dm.trial_oracle(trial('t', 'c', 0.02, 50, [off], [on]), CONTROL, noise_aware=False)
            for off, on in cases] == [campaign.oracle(p, CONTROL) for p in pairs]


def test_a_placement_that_fails_more_often_loses_whatever_its_values():
    t = trial('t', 'c', 0.02, 50, [run(0.5), run(0.2, ABORTED)], [run(1.0), run(1.0)])
    assert dm.trial_oracle(t, CONTROL) == ONLOAD


# ---------------------------------------------------------------- values and regret
def test_placement_value_counts_a_failure_as_a_redo_in_the_other_placement_plus_one_task():
    t = trial('t', 'c', 0.02, 50, [run(0.2, ABORTED)], [run(1.2), run(1.0)])
    assert dm.placement_value(t.onload, t.offload, CONTROL) == pytest.approx(1.1)
    assert dm.placement_value(t.offload, t.onload, CONTROL) == pytest.approx(2.1)     # 1.1 redone + 1 lost
    both = trial('t', 'c', 0.02, 50, [run(0.2, ABORTED)], [run(1.7, TIMED_OUT)])
    assert dm.placement_value(both.offload, both.onload, CONTROL) == pytest.approx(2.0)  # the control's 1 + 1
    assert dm.regret(t, OFFLOAD, ONLOAD, CONTROL) == pytest.approx(1.0)
    assert dm.regret(t, ONLOAD, ONLOAD, CONTROL) == 0.0
    close = trial('t', 'c', 0.02, 50, [run(0.99)], [run(1.0)])
    assert dm.regret(close, OFFLOAD, EITHER, CONTROL) == dm.regret(close, ONLOAD, EITHER, CONTROL) == 0.0
    far = trial('t', 'c', 0.02, 50, [run(0.8)], [run(1.0)])
    assert dm.regret(far, ONLOAD, OFFLOAD, CONTROL) == pytest.approx(0.2)


def test_change_pct():
    assert dm.change_pct([88.0, 88.0], [85.6]) == pytest.approx(-2.4 / 88 * 100)
    assert math.isnan(dm.change_pct([], [1.0])) and math.isnan(dm.change_pct([1.0], [math.nan]))


# ---------------------------------------------------------------- thresholds
def test_best_threshold_finds_the_boundary_and_counts_either_as_right():
    c_l = [0.01, 0.03, 0.05, 0.07, 0.09, 0.03, 0.03]
    r_bw = [50, 50, 50, 50, 50, 2.0, 20.0]
    labels = [OFFLOAD, OFFLOAD, EITHER, ONLOAD, ONLOAD, ONLOAD, OFFLOAD]
    th = campaign.best_threshold(c_l, r_bw, labels)
    assert 0.03 < th.rtt <= 0.05 + 1e-6 and 2.0 <= th.r_bw < 20.0 and th.accuracy == 1.0
    assert campaign.best_threshold([0.1, 0.2], [5, 5], [ONLOAD, EITHER]) == campaign.Threshold(0.0, math.inf, 1.0)
    assert math.isnan(campaign.best_threshold([], [], []).accuracy)


def _old_static_rule_fit(rows):
    """The fit as a pure-Python double loop, for the behaviour of static_rule_fit on the robot's rows."""
    best, best_ok = (0.0, math.inf), sum(1 for r in rows if r.label == ONLOAD)
    for a in [x + 1e-9 for x in sorted({r.c_l for r in rows})]:
        for b in [-math.inf] + sorted({r.r_bw for r in rows}):
            ok = sum(1 for r in rows if (r.c_l < a and r.r_bw > b) == (r.label == OFFLOAD))
            if ok > best_ok:
                best, best_ok = (a, b), ok
    return best


def _training_row(c_l, r_bw, label, task='latency_task', t=0.0):
    return Row(r_bw=r_bw, c_l=c_l, decision=label, mission_status=COMPLETED, b_task=0.003, t_task=30.0,
               timestamp=1.7e9 + t, task=task, location='corridor', placement='', rtt_spread=0.001, loss=0.0,
               profile_method='probe', value=1.0, good=True, label=label, explored=False, source='local')


def test_static_rule_fit_is_the_best_threshold_of_the_rows_labels():
    rng = random.Random(4)
    for _ in range(20):
        rows = [_training_row(round(rng.uniform(0, 0.2), 3), round(rng.uniform(0.5, 60), 1),
                              rng.choice([OFFLOAD, ONLOAD])) for _ in range(rng.randint(0, 25))]
        assert campaign.static_rule_fit(rows) == _old_static_rule_fit(rows)


# ---------------------------------------------------------------- the measures of a two-task campaign
GRID_C_L = (0.01, 0.02, 0.03, 0.15, 0.2, 0.25)
GRID_R_BW = (1.5, 2.0, 40.0, 60.0, 80.0)


def latency_bound(c_l, r_bw):
    return OFFLOAD if c_l < 0.05 else ONLOAD


def bandwidth_bound(c_l, r_bw):
    return OFFLOAD if r_bw > 20 else ONLOAD


def two_task_campaign():
    """Two tasks whose boundaries differ (one by RTT, one by R_bw): 2 training and 4 held-out trials each, the
    offload-better trials 0.2 cheaper offloaded, the onload-better ones 0.5 dearer; 40 right training rows per
    task, then 20 wrong ones at the held-out points (a k-NN on more than 40 rows would follow them)."""
    held_points = ((0.02, 2.0), (0.02, 50.0), (0.15, 2.0), (0.15, 50.0))
    ts, rows = [], []
    for task, rule in (('latency_task', latency_bound), ('bandwidth_task', bandwidth_bound)):
        ts += [trial(task, f'{task}-train{i}', 0.3, 1.2, [run(1.5)], [run(1.0)]) for i in range(2)]
        for i, (c_l, r_bw) in enumerate(held_points):
            better = rule(c_l, r_bw)
            ts.append(trial(task, f'{task}-held{i}', c_l, r_bw, [run(0.8 if better == OFFLOAD else 1.5)],
                            [run(1.0)]))
        grid = [(c, r) for c in GRID_C_L for r in GRID_R_BW]
        right = grid + grid[:10]
        rows += [_training_row(c, r, rule(c, r), task, i) for i, (c, r) in enumerate(right)]
        rows += [_training_row(c, r, ONLOAD if rule(c, r) == OFFLOAD else OFFLOAD, task, 100 + i)
                 for i, (c, r) in enumerate(held_points * 5)]
    controls = {'latency_task': CONTROL, 'bandwidth_task': CONTROL}
    return ts, controls, rows


FIGURES = dm.Figures(4.9, math.nan, 55.0, 160.0, -2.7, -10.0, 3.5)


def test_measures_of_a_two_task_campaign():
    ts, controls, rows = two_task_campaign()
    m = dm.measures(ts, controls, rows, SETTINGS, test_fraction=2 / 3, figures=FIGURES)
    s = m.summary
    assert list(s) == list(dm.SUMMARY_KEYS) + ['per_task']
    assert s['tasks'] == ['latency_task', 'bandwidth_task'] and s['training_conditions'] == 4
    assert s['offload_better_share'] == pytest.approx(4 / 12)
    assert s['knn_noise_aware_accuracy_40'] == 1.0 and s['regret_knn'] == 0.0
    # a-priori regrets on the 8 held-out trials (a wrong onload costs 0.2, a wrong offload 0.5):
    # always onload 4 x 0.2, always offload 4 x 0.5, cold start (0.1 s, 10) 2 x 0.2, RTT < 50 ms 0.5 + 0.2
    per = s['per_task']
    rules = {r: (per['latency_task']['regret_a_priori'][r] + per['bandwidth_task']['regret_a_priori'][r]) / 2
             for r in per['latency_task']['regret_a_priori']}
    assert rules == pytest.approx({dm.ALWAYS_ONLOAD: 0.8 / 8, dm.ALWAYS_OFFLOAD: 2.0 / 8,
                                   dm.COLD_START_RULE: 0.4 / 8, dm.RTT_RULE: 0.7 / 8})
    assert s['best_a_priori_rule'] == dm.COLD_START_RULE and s['regret_best_a_priori'] == pytest.approx(0.05)
    # one threshold for both tasks is right on at most 6 of 8 (two points have opposite labels); each task's own: 4/4
    assert s['knn_minus_best_single_threshold_pts'] == pytest.approx(25.0)
    assert per['latency_task']['best_threshold']['accuracy'] == per['bandwidth_task']['best_threshold']['accuracy'] == 1
    assert per['latency_task']['knn_rows'] == 40 and per['bandwidth_task']['offload_better'] == 2
    assert per['latency_task']['best_a_priori_rule'] == dm.RTT_RULE
    assert (s['crossing_rbw'], s['crossing_rbw_with_migration'], s['hours']) == (4.9, None, 3.5)
    assert list(m.why_null) == ['crossing_rbw_with_migration']
    json.dumps(s, allow_nan=False)                                 # strict JSON: no NaN anywhere


def test_a_k_nn_on_more_than_40_rows_would_follow_the_wrong_ones():
    ts, controls, rows = two_task_campaign()
    s = dm.measures(ts, controls, rows, SETTINGS, 2 / 3, FIGURES, max_rows=60).summary
    assert s['knn_noise_aware_accuracy_40'] == 0.0 and s['regret_knn'] == pytest.approx((4 * 0.2 + 4 * 0.5) / 8)


def test_without_held_out_conditions_the_measures_are_null_with_a_reason():
    ts, controls, rows = two_task_campaign()
    m = dm.measures(ts, controls, rows, SETTINGS, 0.0, dm.Figures(*[math.nan] * 7))
    assert m.summary['training_conditions'] == 12 and m.summary['tasks'] == ['latency_task', 'bandwidth_task']
    nulls = [k for k in dm.SUMMARY_KEYS if m.summary[k] is None]
    assert nulls == [k for k in dm.SUMMARY_KEYS if k not in ('offload_better_share', 'tasks', 'training_conditions')]
    assert set(m.why_null) == set(nulls) and all(m.why_null.values())
    # a task without control values is left out
    only = dm.measures(ts, {'latency_task': CONTROL}, rows, SETTINGS, 2 / 3, FIGURES).summary
    assert only['tasks'] == ['latency_task'] and only['training_conditions'] == 2


# ---------------------------------------------------------------- campaign_summary.json by the analysis
def analyse(tmp_path, monkeypatch, rows, learned):
    """``rows`` and the robot's ``learned`` rows written as a campaign's results.tsv and training_set.tsv in
    ``tmp_path/campaign``, analysed by ``exp_campaign.sh --analyse-only`` (control CT 30 s, CB 0.003). Fig. 5-1, a map
    of 14 400 k-NN queries that these tests do not look at, is drawn empty."""
    import matplotlib.pyplot as plt
    from cnr_benchmarks import campaign as script
    from cnr_benchmarks import campaign_figures
    from cnr_mission.core.task import RESULT_COLUMNS
    monkeypatch.setattr(campaign_figures, 'fig_decision_map', lambda a: plt.subplots()[0])
    values = str(tmp_path / 'control_values.yaml')
    write_control_values(values, ControlValues('corridor_round_trip', 30.0, 0.3, 0.003, 0.00003, 20, '2026-11-28',
                                               'test'))
    out = tmp_path / 'campaign'
    out.mkdir()
    with open(out / 'results.tsv', 'w', newline='') as f:
        w = csv.DictWriter(f, RESULT_COLUMNS, delimiter='\t', lineterminator='\n')
        w.writeheader()
        w.writerows(rows)
    (out / 'training_set.tsv').write_text(HEADER + '\n' + ''.join(format_row(r) + '\n' for r in learned))
    assert script.main(['campaign', '--analyse-only', '--out', str(out), '--control-values', values]) == 0


def test_the_analysis_writes_campaign_summary_json_and_its_table(tmp_path, monkeypatch):
    """A 10-condition corridor campaign (offload better on a short RTT): the page and campaign_summary.json from
    --analyse-only, the training set read from the published training_set.tsv beside the rows."""
    out = tmp_path / 'campaign'
    rows, learned, t0 = [], [], 1.8e9
    for i in range(10):
        c_l, r_bw = (0.02, 50.0) if i % 2 else (0.15, 3.0)
        for placement in (ONLOAD, OFFLOAD):
            v = 1.0 if placement == ONLOAD else (0.8 if i % 2 else 1.5)
            label = OFFLOAD if i % 2 else ONLOAD
            start = t0 + 100 * i + (50 if placement == OFFLOAD else 0)
            rows.append(dict(id=f'c{i:04d}-{placement}', condition=f'c{i:04d}', rtt_ms=1000 * c_l, rate_mbit=20,
                             loss=0, force=placement, decision=placement, reason='forced', policy=ONLOAD,
                             confidence=1, votes_offload=0, c_l=c_l, r_bw=r_bw, profile_method='probe', placed=1,
                             placing_time=2.0, redecisions=0, placement='', mission_status=COMPLETED,
                             t_task=30 * v, b_task=0.003 * v, value=v, good=1, label=label, learned=1,
                             wall_start=start, wall_time=40))
            learned.append(_training_row(c_l, r_bw, label, 'corridor_round_trip', start + 30 - 1.7e9))
    analyse(tmp_path, monkeypatch, rows, learned)
    summary = json.loads((out / 'campaign_summary.json').read_text())
    assert list(summary) == list(dm.SUMMARY_KEYS) + ['per_task']
    assert summary['tasks'] == ['corridor_round_trip'] and summary['training_conditions'] == 7
    assert summary['offload_better_share'] == pytest.approx(0.5)
    assert summary['knn_noise_aware_accuracy_40'] == 1.0 and summary['regret_knn'] == 0.0
    assert summary['per_task']['corridor_round_trip']['knn_rows'] == 14
    assert summary['hours'] == pytest.approx((900 + 50 + 40) / 3600)
    page = (out / 'README.md').read_text()
    assert '| `knn_noise_aware_accuracy_40` | goal ≥ 90 %' in page
    assert '| `crossing_rbw` | ≈ 4.9 (Fig. 5-2) |' in page
    assert '| corridor_round_trip | 10 (7 / 3) |' in page
    from cnr_benchmarks.campaign_figures import SUMMARY_BESIDE
    assert list(SUMMARY_BESIDE) == list(dm.SUMMARY_KEYS)      # every key beside the thesis


def test_rows_learned_during_the_runs_of_each_task():
    from cnr_benchmarks.core.decision_measures import learned_during
    runs = [dict(condition='c1', wall_start='100', wall_time='40'),
            dict(condition='c1', wall_start='100', wall_time='40', task='patrol'),
            dict(condition='c2', wall_start='200', wall_time='40')]
    learned = [dataclasses.replace(_training_row(0.02, 50, OFFLOAD, task), timestamp=t)
               for task, t in (('corridor_round_trip', 120), ('corridor_round_trip', 240.5),
                               ('corridor_round_trip', 300), ('patrol', 130))]
    got = learned_during(learned, runs, {('corridor_round_trip', 'c2'), ('patrol', 'c1')}, 'corridor_round_trip')
    assert got == [learned[1], learned[3]]      # c2's row half a second after its end counts; c1's is not a key


# ---------------------------------------------------------------- a learning plan
def test_a_learning_plan_runs_training_conditions_once_and_held_out_ones_repeated_per_placement():
    conditions = campaign.learning_split(campaign.draw_conditions(4, 7, campaign.Ranges(0, 200, 0.5, 50, 0, 0.05)),
                                         0.5)
    assert [c.id for c in conditions] == ['c0001', 'c0002', 'h0003', 'h0004']
    runs = campaign.learning_plan_document('corridor_long', 'corridor', 6.0, conditions, 2)['runs']
    assert [(r['id'], r['force'], r['learn'], r['explore'], r['reuse_profile']) for r in runs[:9]] == [
        ('h0003-onload-1', ONLOAD, False, False, False), ('h0003-offload-1', OFFLOAD, False, False, True),
        ('h0003-onload-2', ONLOAD, False, False, True), ('h0003-offload-2', OFFLOAD, False, False, True),
        ('h0004-onload-1', ONLOAD, False, False, False)] + [
        (f'h0004-{p}-{i}', p, False, False, True) for i, p in ((1, OFFLOAD), (2, ONLOAD), (2, OFFLOAD))] + [
        ('c0001-policy', '', True, True, False)]
    assert runs[-1]['id'] == 'c0002-policy'    # the held-out conditions first, then the training ones in order
    held = [r for r in runs if r['condition'] == 'h0003']
    assert [(r['force'], r['reuse_profile']) for r in held] == [(ONLOAD, False), (OFFLOAD, True), (ONLOAD, True),
                                                                (OFFLOAD, True)]
    assert len(runs) == 2 + 2 * 4 and all(r['link'] == held[0]['link'] for r in held)
    with pytest.raises(ValueError):
        campaign.learning_plan_document('corridor_long', 'corridor', 6.0, conditions, 0)


def test_the_task_runner_reads_a_learning_plan(tmp_path):
    import yaml
    from cnr_mission.core.task import load_plan
    conditions = campaign.learning_split(campaign.draw_conditions(3, 7, campaign.Ranges(0, 200, 0.5, 50, 0, 0.05)),
                                         1 / 3)
    path = tmp_path / 'plan.yaml'
    path.write_text(yaml.safe_dump(campaign.learning_plan_document('corridor_long', 'corridor', 6.0, conditions, 2)))
    plan = load_plan(str(path))
    assert [(r.force, r.learn, r.explore) for r in plan.runs[-2:]] == [('', True, True), ('', True, True)]
    assert len(plan.runs) == 6 and plan.runs[3].reuse_profile and not plan.runs[0].reuse_profile


def test_a_learning_plan_holds_out_its_held_out_conditions_and_trains_on_every_other():
    """Training conditions ran once (no trial); the held-out ones are the held-out trials whatever the fraction,
    and the training conditions are counted from the rows."""
    rows = [_row('c0001', OFFLOAD, COMPLETED, 0.9), _row('c0002', ONLOAD, COMPLETED, 1.0),
            _row('c0003', ONLOAD, COMPLETED, 1.0), _row('c0003', OFFLOAD, COMPLETED, 1.2)]
    for cid in ('h0004', 'h0005'):
        rows += [_row(cid, ONLOAD, COMPLETED, 1.0), _row(cid, OFFLOAD, COMPLETED, 0.8)] * 2
    ts = dm.trials(rows, 'latency_task')
    train, held = dm.split(ts, 0.9)
    assert [t.condition for t in train] == ['c0003'] and [t.condition for t in held] == ['h0004', 'h0005']
    assert len(held[0].offload) == 2
    keys = dm.training_keys(rows, ts, 0.9, 'latency_task')
    assert keys == [('latency_task', 'c0001'), ('latency_task', 'c0002'), ('latency_task', 'c0003')]
    m = dm.measures(ts, {'latency_task': CONTROL}, [], SETTINGS, 0.9, FIGURES, trained_on=keys)
    assert m.summary['training_conditions'] == 3 and m.summary['per_task']['latency_task']['held_out'] == 2
    # a paired campaign (no held-out ids) splits by the fraction, as before
    paired = [r for r in rows if not campaign.held_out(r['condition'])]
    assert dm.training_keys(paired, dm.trials(paired, 'latency_task'), 0.0, 'latency_task') == \
        [('latency_task', 'c0003')]


def test_the_analysis_of_a_learning_plan(tmp_path, monkeypatch):
    """10 training conditions run once each (the robot's choice, learned) and 4 held-out ones run twice per
    placement: the held-out ones are the measured trials, the robot's 10 rows its k-NN's."""
    out = tmp_path / 'campaign'
    rows, learned, t0 = [], [], 1.8e9

    def add(cid, i, placement, learn, start):
        c_l, r_bw = (0.02, 50.0) if i % 2 else (0.15, 3.0)
        v = 1.0 if placement == ONLOAD else (0.8 if i % 2 else 1.5)
        label = OFFLOAD if i % 2 else ONLOAD
        rows.append(dict(id=f'{cid}-{placement}', condition=cid, rtt_ms=1000 * c_l, rate_mbit=20, loss=0,
                         force='' if learn else placement, decision=placement, reason='knn' if learn else 'forced',
                         policy=label, confidence=1, votes_offload=0, c_l=c_l, r_bw=r_bw, profile_method='probe',
                         placed=1, placing_time=0.2, redecisions=0, placement='', mission_status=COMPLETED,
                         t_task=30 * v, b_task=0.003 * v, value=v, good=1, label=label, learned=int(learn),
                         wall_start=start, wall_time=40))
        if learn:
            learned.append(_training_row(c_l, r_bw, label, 'corridor_round_trip', start + 30 - 1.7e9))
    for i in range(10):
        add(f'c{i:04d}', i, OFFLOAD if i % 2 else ONLOAD, True, t0 + 50 * i)
    for j, i in enumerate(range(10, 14)):
        for k, placement in enumerate((ONLOAD, OFFLOAD, ONLOAD, OFFLOAD)):
            add(f'h{i:04d}', i, placement, False, t0 + 500 + 200 * j + 50 * k)
    analyse(tmp_path, monkeypatch, rows, learned)
    summary = json.loads((out / 'campaign_summary.json').read_text())
    assert summary['training_conditions'] == 10 and summary['per_task']['corridor_round_trip']['held_out'] == 4
    assert summary['per_task']['corridor_round_trip']['knn_rows'] == 10
    assert summary['knn_noise_aware_accuracy_40'] == 1.0 and summary['offload_better_share'] == pytest.approx(0.5)
    page = (out / 'README.md').read_text()
    assert '10 training conditions run once each in the placement the robot chose, 4 held-out' in page
    assert 'Without a pair' not in page


def test_a_plan_of_two_tasks_deals_the_conditions_in_turn_and_holds_out_each_tasks_last(tmp_path):
    import yaml
    from cnr_mission.core.task import load_plan
    drawn = campaign.draw_conditions(8, 7, campaign.Ranges(0, 250, 0.5, 50, 0, 0.1))
    conditions = campaign.learning_split(campaign.assign_tasks(drawn, ['corridor_long', 'corridor_round_trip']), 0.25)
    assert [(c.id, c.task) for c in conditions] == [
        ('c0001', 'corridor_long'), ('c0002', 'corridor_round_trip'), ('c0003', 'corridor_long'),
        ('c0004', 'corridor_round_trip'), ('c0005', 'corridor_long'), ('c0006', 'corridor_round_trip'),
        ('h0007', 'corridor_long'), ('h0008', 'corridor_round_trip')]
    assert campaign.assign_tasks(drawn, ['corridor_long']) == drawn
    path = tmp_path / 'plan.yaml'
    path.write_text(yaml.safe_dump(campaign.learning_plan_document('corridor_long', 'corridor', 6.0, conditions, 2)))
    plan = load_plan(str(path))
    assert plan.tasks == ['corridor_long', 'corridor_round_trip']
    assert [plan.task_of(r) for r in plan.runs if r.learn][:2] == ['corridor_long', 'corridor_round_trip']
    assert {plan.task_of(r) for r in plan.runs if r.condition == 'h0008'} == {'corridor_round_trip'}


def test_a_plan_refuses_a_profile_reused_from_another_tasks_run(tmp_path):
    from cnr_mission.core.task import load_plan
    from cnr_params import ConfigError
    path = tmp_path / 'plan.yaml'
    path.write_text("""task: corridor_long
location: corridor
settle: 6.0
runs:
- {id: a, condition: c1, force: onload, decide: true, learn: false, explore: false, reuse_profile: false}
- {id: b, condition: c1, force: offload, decide: true, learn: false, explore: false, reuse_profile: true,
   task: corridor_round_trip}
""")
    with pytest.raises(ConfigError, match='reuse_profile'):
        load_plan(str(path))


def test_the_analysis_of_a_two_task_learning_plan(tmp_path, monkeypatch):
    """Two tasks dealt conditions in turn (the rows' task column), each with its control values and published
    training set: the figures and the accuracy table are the first task's, campaign_summary.json every task's."""
    import matplotlib.pyplot as plt
    from cnr_benchmarks import campaign as script
    from cnr_benchmarks import campaign_figures
    from cnr_mission.core.task import RESULT_COLUMNS
    monkeypatch.setattr(campaign_figures, 'fig_decision_map', lambda a: plt.subplots()[0])
    tasks = ('corridor_long', 'corridor_round_trip')
    values = str(tmp_path / 'control_values.yaml')
    for task, ct in zip(tasks, (70.0, 21.0)):
        write_control_values(values, ControlValues(task, ct, 0.3, 0.003, 0.00003, 8, '2026-11-29', 'test'))
    out = tmp_path / 'campaign'
    out.mkdir()
    rows, learned, t0 = [], {t: [] for t in tasks}, 1.8e9

    def add(cid, task, i, placement, learn, start):
        ct = 70.0 if task == tasks[0] else 21.0
        c_l, r_bw = (0.02, 50.0) if i % 2 else (0.15, 3.0)
        v = 1.0 if placement == ONLOAD else (0.8 if i % 2 else 1.5)
        label = OFFLOAD if i % 2 else ONLOAD
        rows.append(dict(id=f'{cid}-{placement}-{start}', condition=cid, task=task, rtt_ms=1000 * c_l, rate_mbit=20,
                         loss=0, force='' if learn else placement, decision=placement,
                         reason='knn' if learn else 'forced', policy=label, confidence=1, votes_offload=0, c_l=c_l,
                         r_bw=r_bw, profile_method='probe', placed=1, placing_time=0.2, redecisions=0, placement='',
                         mission_status=COMPLETED, t_task=ct * v, b_task=0.003 * v, value=v, good=1, label=label,
                         learned=int(learn), wall_start=start, wall_time=40))
        if learn:
            learned[task].append(_training_row(c_l, r_bw, label, task, start + 30 - 1.7e9))
    for i in range(12):
        add(f'c{i:04d}', tasks[i % 2], i // 2, OFFLOAD if (i // 2) % 2 else ONLOAD, True, t0 + 50 * i)
    for j, i in enumerate(range(12, 16)):
        for k, placement in enumerate((ONLOAD, OFFLOAD, ONLOAD, OFFLOAD)):
            add(f'h{i:04d}', tasks[i % 2], j, placement, False, t0 + 700 + 200 * j + 50 * k)
    with open(out / 'results.tsv', 'w', newline='') as f:
        w = csv.DictWriter(f, RESULT_COLUMNS, delimiter='\t', lineterminator='\n')
        w.writeheader()
        w.writerows(rows)
    for task, name in zip(tasks, ('training_set.tsv', 'training_set_corridor_round_trip.tsv')):
        (out / name).write_text(HEADER + '\n' + ''.join(format_row(r) + '\n' for r in learned[task]))
    assert script.main(['campaign', '--analyse-only', '--task', ','.join(tasks), '--out', str(out),
                        '--control-values', values]) == 0
    summary = json.loads((out / 'campaign_summary.json').read_text())
    assert summary['tasks'] == list(tasks) and summary['training_conditions'] == 12
    assert [summary['per_task'][t]['held_out'] for t in tasks] == [2, 2]
    assert [summary['per_task'][t]['knn_rows'] for t in tasks] == [6, 6]
    page = (out / 'README.md').read_text()
    assert 'Tasks corridor_long, corridor_round_trip' in page
    assert '6 training conditions run once each' in page              # the first task's paragraph
