"""The network-aware task loop's ROS-free cores: the advisor (decide, re-decide, evaluate, learn), the task
definitions and plans (cnr_mission.core.task) and the campaign's conditions and analysis
(cnr_benchmarks.core.campaign). Unit tests only: no master."""
import ast
import dataclasses
import math
import os

import pytest
import yaml

from cnr_benchmarks.core import campaign
from cnr_mission.core.task import (ABORTED, COMPLETED, GAVE_UP, OTHER, SUCCEEDED, TIMED_OUT, TOO_LONG,
                                   append_result, battery_used, evaluable, load_plan, load_task, mission_status, read_results,
                                   resolve_force)
from cnr_params import ConfigError, Section
from network_monitor.core.advisor import FORCED, AdvisorError, Profile, TaskAdvisor
from network_monitor.core.decision import COLD_START, KNN
from network_monitor.core.decision_config import load_decision_config
from network_monitor.core.evaluation import (OFFLOAD, ONLOAD, ControlValues, Outcome, write_control_values)
from network_monitor.core.training import TrainingSet

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONTROL = ControlValues('corridor_round_trip', 30.0, 2.0, 0.003, 0.0002, 20, '2026-11-24', 'test')
GOOD = Profile(c_l=0.01, r_bw=80.0, rtt_spread=0.001, loss=0.0, method='probe')
BAD = Profile(c_l=0.25, r_bw=1.2, rtt_spread=0.01, loss=0.02, method='probe')


def advisor(tmp_path, **redecision):
    cfg = load_decision_config(os.path.join(WS, 'config', 'decision.yaml'))
    control = str(tmp_path / 'control_values.yaml')
    write_control_values(control, CONTROL)
    e = dataclasses.replace(cfg.decision.exploration, rate=0.0, seed=0)
    cfg = dataclasses.replace(cfg, training_dir=str(tmp_path / 'training'), control_values=control,
                              decision=dataclasses.replace(cfg.decision, exploration=e),
                              redecision=dataclasses.replace(cfg.redecision, **redecision))
    return TaskAdvisor(cfg)


@pytest.mark.parametrize('path', ['network_monitor/src/network_monitor/core/advisor.py',
                                  'cnr_mission/src/cnr_mission/core/task.py',
                                  'cnr_benchmarks/src/cnr_benchmarks/core/campaign.py'])
def test_cores_never_import_rospy(path):
    with open(os.path.join(WS, 'src', path), encoding='utf-8') as f:
        tree = ast.parse(f.read())
    imported = {a.name.split('.')[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split('.')[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert 'rospy' not in imported


# ---------------------------------------------------------------- advisor
def test_cold_start_then_knn_learns_from_evaluated_runs(tmp_path):
    a = advisor(tmp_path)
    d, hosts, warnings = a.begin('corridor_round_trip', 'corridor', GOOD, 0.0)
    assert (d.decision, d.reason, hosts, warnings) == (OFFLOAD, COLD_START, {'move_base': 'cloud'}, [])
    a.placed(0.0, 1)
    row, control = a.finish(COMPLETED, 36.0, 0.0036, 1.7e9, learn=True)     # 20 % worse than the control: bad
    assert row.value == pytest.approx(1.2) and not row.good and row.label == ONLOAD
    assert row.placement == 'move_base=cloud' and row.c_l == GOOD.c_l and control == CONTROL
    with pytest.raises(AdvisorError):
        a.finish(COMPLETED, 30.0, 0.003, 1.7e9, learn=True)                 # nothing running any more
    for i in range(4):                                                      # the set fills to k rows
        a.begin('corridor_round_trip', 'corridor', GOOD, 10.0 + i, force=ONLOAD)
        a.placed(10.0 + i, 0)
        a.finish(COMPLETED, 29.0, 0.0029, 1.7e9 + i + 1, learn=True)        # onload was fine: label onload
    d, _, _ = a.begin('corridor_round_trip', 'corridor', GOOD, 20.0)
    assert (d.decision, d.reason, d.votes) == (ONLOAD, KNN, {OFFLOAD: 0, ONLOAD: 5})
    rows, _ = TrainingSet(str(tmp_path / 'training'), 'corridor_round_trip', 'corridor').read()
    assert len(rows) == 5 and [r.explored for r in rows] == [False] + [True] * 4   # forced against the policy


def test_forced_runs_keep_the_policy_and_a_failure_labels_the_other(tmp_path):
    a = advisor(tmp_path)
    d, hosts, _ = a.begin('corridor_round_trip', 'corridor', BAD, 0.0, force=OFFLOAD)
    assert (d.decision, d.reason, d.policy, hosts) == (OFFLOAD, FORCED, ONLOAD, {'move_base': 'cloud'})
    a.placed(0.0, 1)
    row, _ = a.finish(ABORTED, 12.0, 0.001, 1.7e9, learn=True)
    assert row.label == ONLOAD and row.explored and not row.good


def test_unknown_profile_onloads_and_is_not_learned(tmp_path):
    a = advisor(tmp_path)
    lost = Profile(math.nan, math.nan, math.nan, math.nan, 'none', alive=False)
    d, hosts, _ = a.begin('corridor_round_trip', 'corridor', lost, 0.0)
    assert d.decision == ONLOAD and hosts == {'move_base': 'robot'}
    a.placed(0.0, 0)
    a.finish(COMPLETED, 30.0, 0.003, 1.7e9, learn=True)
    assert TrainingSet(str(tmp_path / 'training'), 'corridor_round_trip', 'corridor').read()[0] == []


def test_bad_requests_are_refused(tmp_path):
    a = advisor(tmp_path)
    for args in (('nope', 'corridor'), ('corridor_round_trip', 'moon')):
        with pytest.raises(AdvisorError):
            a.begin(*args, GOOD, 0.0)
    with pytest.raises(AdvisorError):
        a.begin('corridor_round_trip', 'corridor', GOOD, 0.0, force='sideways')
    a.begin('corridor_round_trip', 'corridor', GOOD, 0.0)
    with pytest.raises(AdvisorError):
        a.begin('corridor_round_trip', 'corridor', GOOD, 1.0)               # one task at a time


def test_mid_task_redecision_waits_for_the_dwell_and_respects_the_budget(tmp_path):
    a = advisor(tmp_path, dwell=2.0, max_migrations=1, window=30.0, margin=0.8)
    a.begin('corridor_round_trip', 'corridor', GOOD, 0.0)                   # cold start: offload
    a.placed(0.0, 1)                                                        # that migration uses the budget
    assert a.observe(BAD, 1.0) is None
    assert a.observe(BAD, 10.0) is None                                     # dwell met, budget not (window)
    switch = a.observe(BAD, 31.0)
    assert switch is not None and switch[0] == ONLOAD
    assert a.observe(GOOD, 40.0) is None and a.observe(GOOD, 50.0) is None  # budget: one per 30 s
    row, _ = a.finish(COMPLETED, 30.0, 0.003, 1.7e9, learn=True)
    assert row.placement == 'move_base=cloud>robot' and row.decision == OFFLOAD
    # a forced placement is held for the whole task (a paired run measures that placement)
    a.begin('corridor_round_trip', 'corridor', GOOD, 100.0, force=OFFLOAD)
    a.placed(100.0, 1)
    assert all(a.observe(BAD, t) is None for t in (101.0, 120.0, 140.0, 200.0))
    assert a.finish(COMPLETED, 30.0, 0.003, 1.7e9 + 1, learn=True)[0].placement == 'move_base=cloud'


def test_an_offloaded_modules_own_traffic_does_not_bring_it_home(tmp_path):
    """Mid-task, with move_base on the cloud, its sensor streams are on the link: R_bw as measured falls from 124
    at home to 7.3 (a 25 Mbit/s link, 3 Mbit/s in use), which a set profiled at home reads as a slow link; the
    re-decision reads it as if the modules were home (r_bw_at_home) and stays. A link that really degrades
    (a 1.2 Mbit/s link: 0.2 Mbit/s left beside the scans, now squeezed to 1 Mbit/s) still brings them home."""
    from network_monitor.core.advisor import r_bw_at_home
    home = dataclasses.replace(GOOD, r_bw=124.0, a_bw=24.8e6, c_bw=0.15e6)     # C_bw below the 0.2 Mbit/s floor
    away = dataclasses.replace(GOOD, r_bw=7.3, a_bw=22.0e6, c_bw=3.0e6)
    assert r_bw_at_home(away, home) == pytest.approx((22.0e6 + 2.85e6) / 0.2e6)
    assert r_bw_at_home(dataclasses.replace(away, a_bw=math.nan), home) == 7.3
    a = advisor(tmp_path, dwell=2.0, max_migrations=1, window=30.0, margin=0.8)
    a.begin('corridor_round_trip', 'corridor', home, 0.0)                   # cold start: offload
    assert a.running.placement == OFFLOAD
    a.placed(0.0, 0)
    assert all(a.observe(away, t) is None for t in (1.0, 5.0, 10.0, 40.0))  # the cold-start rule: R_bw > 10 at home
    slow = dataclasses.replace(away, r_bw=0.2, a_bw=0.2e6, c_bw=1.0e6)     # at home: (0.2 + 0.85) / 0.2 = 5.25
    a.observe(slow, 41.0)
    switch = a.observe(slow, 44.0)
    assert switch is not None and switch[0] == ONLOAD


# ---------------------------------------------------------------- tasks and plans
def test_the_shipped_task_and_status_rules():
    t = load_task(Section.from_file(os.path.join(WS, 'config', 'scenarios', 'corridor.yaml')), 'corridor_round_trip')
    assert t.start == (0.5, 0.0, 0.0) and len(t.goals) == 2 and t.goal_timeout > 0
    assert mission_status([SUCCEEDED, SUCCEEDED], 2) == COMPLETED
    assert mission_status([SUCCEEDED, GAVE_UP], 2) == ABORTED
    assert mission_status([TOO_LONG], 2) == TIMED_OUT
    assert mission_status([SUCCEEDED], 2) == ABORTED                        # stopped before the end
    assert battery_used(0.80, 0.795) == pytest.approx(0.005)      # BatteryState.percentage: 0..1
    assert evaluable(battery_used(0.80, 0.795))


def test_a_run_without_a_battery_reading_has_no_b_task_and_is_never_evaluated():
    assert math.isnan(battery_used(None, 0.795)) and math.isnan(battery_used(0.8, None))
    assert not evaluable(battery_used(None, None)) and not evaluable(math.nan)
    with pytest.raises(ConfigError, match='tasks.nope'):
        load_task(Section({'tasks': {}}, 'x.yaml'), 'nope')


def test_plans_resolve_other_and_refuse_bad_runs(tmp_path):
    doc = campaign.plan_document('corridor_round_trip', 'corridor', 6.0,
                                 campaign.draw_conditions(3, 7, campaign.Ranges(0, 200, 0.5, 50, 0, 0.05)))
    p = tmp_path / 'plan.yaml'
    p.write_text(yaml.safe_dump(doc))
    plan = load_plan(str(p))
    assert len(plan.runs) == 6 and plan.runs[0].link.rtt_ms <= 200 and plan.runs[0].link == plan.runs[1].link
    # per condition: onload on a new profile (the modules home), then offload on the same profile
    assert [(r.force, r.reuse_profile) for r in plan.runs[:2]] == [(ONLOAD, False), (OFFLOAD, True)]
    assert resolve_force(OTHER, OFFLOAD) == ONLOAD and resolve_force('', None) == ''
    with pytest.raises(ValueError):
        resolve_force(OTHER, '')
    del doc['runs'][1]['reuse_profile']
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r'runs\[1\]\.reuse_profile'):
        load_plan(str(p))
    doc['runs'][1]['reuse_profile'] = True
    doc['runs'][0]['force'] = 'other'
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r'runs\[0\]\.force'):
        load_plan(str(p))
    doc['runs'][0].update(force='', id=doc['runs'][1]['id'])
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match='id'):
        load_plan(str(p))


def test_results_are_appended_and_a_torn_line_is_reported(tmp_path):
    path = str(tmp_path / 'results.tsv')
    append_result(path, dict(id='a', condition='c1', t_task=30.5, good=True))
    with open(path, 'a') as f:
        f.write('torn\tline')                                                # a crash mid-row
    append_result(path, dict(id='b', condition='c1'))
    rows, warnings = read_results(path)
    assert [r['id'] for r in rows] == ['a', 'b'] and rows[0]['t_task'] == '30.5' and rows[0]['good'] == '1'
    assert len(warnings) == 1 and 'results.tsv:3' in warnings[0]


def test_the_local_remote_plan_alternates_forced_placements_and_its_spread_counts_completed_runs(tmp_path):
    p = tmp_path / 'plan.yaml'
    p.write_text(yaml.safe_dump(campaign.local_remote_plan('corridor_round_trip', 'corridor', 6.0, 3)))
    plan = load_plan(str(p))
    assert [r.force for r in plan.runs] == [ONLOAD, OFFLOAD] * 3
    assert all(r.decide and not r.learn and not r.explore and r.link is None for r in plan.runs)
    rows = [dict(force=ONLOAD, mission_status=COMPLETED, t_task='20'),
            dict(force=ONLOAD, mission_status=COMPLETED, t_task='24'),
            dict(force=ONLOAD, mission_status=TIMED_OUT, t_task='90'),
            dict(force=OFFLOAD, mission_status=COMPLETED, t_task='19')]
    on, off = campaign.spread(rows, ONLOAD, 't_task'), campaign.spread(rows, OFFLOAD, 't_task')
    assert (on.n, on.runs, on.mean) == (2, 3, 22.0) and on.sd == pytest.approx(2 ** 1.5)
    assert (off.n, off.mean) == (1, 19.0) and math.isnan(off.sd)


# ---------------------------------------------------------------- campaign
def test_elapsed_time_counts_what_happens_between_runs_but_not_a_resume_pause():
    rows = [dict(wall_start='100', wall_time='40'), dict(wall_start='145', wall_time='30'),
            dict(wall_start='5000', wall_time='40'), dict(wall_start='5044', wall_time='bad'),
            dict(wall_start='5046', wall_time='20')]
    # 100 -> 145 (45 s with the gap), then 30 s (stopped, resumed at 5000), 5000 -> 5046 (46 s), 20 s
    assert campaign.elapsed_time(rows) == pytest.approx(45 + 30 + 46 + 20)
    assert campaign.elapsed_time([]) == 0.0


def test_conditions_are_reproducible_and_in_range():
    r = campaign.Ranges(0, 200, 0.5, 50, 0, 0.05)
    a, b = campaign.draw_conditions(50, 3, r), campaign.draw_conditions(50, 3, r)
    assert a == b and a != campaign.draw_conditions(50, 4, r)
    assert campaign.draw_conditions(10, 3, r, first=41) == a[40:]            # the i-th depends on the seed only
    assert all(0 <= c.rtt_ms <= 200 and 0.5 <= c.rate <= 50 and 0 <= c.loss <= 0.05 for c in a)


def _result(cid, run, decision, status, t, b, rtt=20.0, c_l=0.02, r_bw=50.0):
    return dict(id=f'{cid}-{run}', condition=cid, decision=decision, mission_status=status, t_task=str(t),
                b_task=str(b), rtt_ms=str(rtt), rate_mbit='20', loss='0', c_l=str(c_l), r_bw=str(r_bw),
                reason='knn')


def test_pairs_and_oracle():
    rows = [_result('c1', 'decided', OFFLOAD, COMPLETED, 28, 0.0027), _result('c1', 'other', ONLOAD, COMPLETED, 30, 0.003),
            _result('c2', 'decided', ONLOAD, COMPLETED, 30, 0.003), _result('c2', 'other', OFFLOAD, ABORTED, 9, 0.001),
            _result('c3', 'decided', ONLOAD, COMPLETED, 30, 0.003),          # unpaired: left out
            _result('c4', 'decided', ONLOAD, COMPLETED, 30, 0.003),
            dict(_result('c4', 'other', OFFLOAD, ABORTED, 9, 0.001), placed='0')]   # placement not made: out
    ps = campaign.pairs(rows)
    assert [p.condition for p in ps] == ['c1', 'c2']
    assert [campaign.oracle(p, CONTROL) for p in ps] == [OFFLOAD, ONLOAD]
    assert ps[1].offload == Outcome(9.0, 0.001, ABORTED)


def test_pairs_of_onload_first_plans_take_the_first_runs_policy_as_the_decision():
    def run(cid, placement, policy, learned='1', c_l=0.02):
        r = _result(cid, placement, placement, COMPLETED, 30, 0.003, c_l=c_l)
        r.update(force=placement, policy=policy, reason='forced', learned=learned)
        return r
    rows = []
    for i in range(4):                                  # 8 rows learned: k = 5 reached after the third condition
        rows += [run(f'c{i}', ONLOAD, OFFLOAD if i % 2 else ONLOAD), run(f'c{i}', OFFLOAD, 'ignored')]
    rows += [run('c9', ONLOAD, ONLOAD, learned='0', c_l=math.nan), run('c9', OFFLOAD, ONLOAD, learned='0')]
    ps = campaign.pairs(rows, k=5)
    assert [(p.decided, p.reason) for p in ps] == [(ONLOAD, 'cold_start'), (OFFLOAD, 'cold_start'),
                                                   (ONLOAD, 'cold_start'), (OFFLOAD, 'knn'), (ONLOAD, 'no_profile')]
    assert ps[0].offload_row['id'] == 'c0-offload' and ps[0].onload_row['id'] == 'c0-onload'


def test_noise_aware_oracle_calls_pairs_within_the_control_noise_either():
    tol = campaign.noise_tolerance(CONTROL)         # sd 2/30 and 0.0002/0.003: each 6.7 %
    assert tol == pytest.approx(2 * math.sqrt(2) * 0.5 * math.hypot(2 / 30, 0.0002 / 0.003))
    close = [_result('c1', 'decided', OFFLOAD, COMPLETED, 30.6, 0.003), _result('c1', 'other', ONLOAD, COMPLETED, 30, 0.003)]
    far = [_result('c2', 'decided', OFFLOAD, COMPLETED, 40, 0.004), _result('c2', 'other', ONLOAD, COMPLETED, 30, 0.003)]
    failed = [_result('c3', 'decided', OFFLOAD, ABORTED, 30, 0.003), _result('c3', 'other', ONLOAD, COMPLETED, 30.1, 0.003)]
    ps = campaign.pairs(close + far + failed)
    assert [campaign.oracle(p, CONTROL) for p in ps] == [ONLOAD, ONLOAD, ONLOAD]           # strict: a winner each
    assert [campaign.oracle(p, CONTROL, tol) for p in ps] == [campaign.EITHER, ONLOAD, ONLOAD]
    assert campaign.agrees(OFFLOAD, campaign.EITHER) and campaign.agrees(ONLOAD, campaign.EITHER)
    assert campaign.agrees(ONLOAD, ONLOAD) and not campaign.agrees(OFFLOAD, ONLOAD)


def test_static_rule_fit_and_learning_curve():
    from test_network_monitor_decision import SETTINGS, row
    rows = [row(0.01 * i, 50.0, OFFLOAD if i < 8 else ONLOAD, timestamp=1.7e9 + i) for i in range(20)]
    a, b = campaign.static_rule_fit(rows)
    assert 0.07 < a <= 0.08 + 1e-6 and campaign.static_rule(a, b, 0.05, 50.0) == OFFLOAD
    held = [campaign.Pair(f'h{i}', 0, 0, 0, 0.01 * i + 0.005, 50.0, OFFLOAD, 'knn', None, None, {}, {})
            for i in range(20)]
    truth = [OFFLOAD if i < 8 else ONLOAD for i in range(20)]
    curve = campaign.learning_curve(rows, 20, held, truth, SETTINGS)
    assert [c['rows'] for c in curve] == [5, 10, 15, 20]
    assert curve[-1]['knn'] >= 0.9 and curve[-1]['static'] >= 0.9
    # the majority placement alone bounds how far any rule can be above never offloading (a static rule)
    assert campaign.constant_accuracy(ONLOAD, truth) == pytest.approx(0.6)
    assert campaign.constant_accuracy(OFFLOAD, truth + [campaign.EITHER]) == pytest.approx(9 / 21)
    # a pair within the noise has a strict winner by chance: what a perfect decision can expect
    assert campaign.strict_ceiling([ONLOAD, OFFLOAD, campaign.EITHER, campaign.EITHER]) == pytest.approx(0.75)
    assert campaign.strict_ceiling([ONLOAD]) == 1.0 and math.isnan(campaign.strict_ceiling([]))


def test_fits_and_crossings():
    fit = campaign.power_fit([1, 2, 4, 8], [40, 20, 10, 5])
    assert fit[0] == pytest.approx(40) and fit[1] == pytest.approx(-1)
    assert campaign.crossing(fit, 10.0) == pytest.approx(4.0)
    assert math.isnan(campaign.crossing(fit, 10.0, 1.0, 3.0))         # outside the measured range
    assert campaign.linear_fit([0, 1, 2], [1, 3, 5]) == pytest.approx((1, 2))
    assert campaign.failure_rtt([(10, COMPLETED), (150, ABORTED), (170, ABORTED), (130, COMPLETED)]) == 140.0
    assert math.isnan(campaign.failure_rtt([(10, COMPLETED)]))


# ---------------------------------------------------------------- shared knowledge on the command line
def test_an_exported_and_imported_set_decides_like_the_one_it_came_from(tmp_path, capsys):
    from network_monitor.training_cli import main as training
    from test_network_monitor_decision import random_rows
    config = os.path.join(WS, 'config', 'decision.yaml')
    a, b = str(tmp_path / 'robot_a'), str(tmp_path / 'robot_b')
    TrainingSet(a, 'corridor_round_trip', 'corridor').append(*random_rows(40, seed=5, inside=True))
    exported = str(tmp_path / 'shared' / 'a.tsv')
    assert training(['--config', config, '--dir', a, 'export', 'corridor_round_trip', 'corridor', exported]) == 0
    assert training(['--config', config, '--dir', b, 'import', 'corridor_round_trip', 'corridor', exported,
                     'robot_a']) == 0
    assert '40 added' in capsys.readouterr().out
    assert training(['--config', config, '--dir', b, 'import', 'corridor_round_trip', 'corridor', exported,
                     'robot_a']) == 0
    assert '0 added, 40 already there' in capsys.readouterr().out
    for rtt_ms, r_bw in ((10, 80.0), (90, 6.0), (150, 2.0), (300, 50.0), (40, 1.5)):
        outs = []
        for d in (a, b):
            assert training(['--config', config, '--dir', d, 'decide', 'corridor_round_trip', 'corridor',
                             str(rtt_ms), str(r_bw)]) == 0
            outs.append(capsys.readouterr().out)
        assert outs[0] == outs[1] and '(knn' in outs[0], outs
    rows, _ = TrainingSet(b, 'corridor_round_trip', 'corridor').read()
    assert {r.source for r in rows} == {'imported:robot_a'}
    assert training(['--config', config, '--dir', b, 'list']) == 0
    assert 'corridor_round_trip@corridor\t40 rows' in capsys.readouterr().out
    assert training(['--config', config, '--dir', b, 'show', 'nope', 'corridor']) == 2      # one line, status 2
    assert 'unknown task' in capsys.readouterr().err


def test_control_of_an_unknown_task_names_both_places_and_exits_2(tmp_path, capsys):
    """exp_control.sh: a task is a goal task of the location's scenario or a monitoring mission of
    config/decision.yaml; anything else is one line naming both, exit 2, nothing run."""
    from cnr_benchmarks import campaign as script
    args = script.parse_args(['control', '--task', 'no_such_task', '--out', str(tmp_path / 'out')])
    assert script.control(args) == 2
    err = capsys.readouterr().err
    assert "'no_such_task'" in err and 'corridor.yaml' in err and 'decision.yaml' in err
    assert not (tmp_path / 'out').exists()


def test_control_results_go_per_task_and_location():
    from cnr_benchmarks import campaign as script
    assert script.parse_args(['control', '--task', 'patrol']).out.endswith('docs/results/control/patrol@corridor')
    assert script.parse_args(['campaign']).out.endswith('docs/results/campaign')


def test_a_slowdown_has_its_own_results_control_values_and_config_copy(tmp_path):
    """--slowdown S: rows, control values and the testbed configuration of that robot CPU cap, never the
    default's; a slowdown below 1 is refused in one line."""
    from cnr_benchmarks import campaign as script
    from cnr_testbed.core.config import load_testbed
    a = script.parse_args(['control', '--slowdown', '6'])
    assert a.out.endswith('control/corridor_round_trip@corridor_slowdown6')
    assert a.control_values.endswith('docs/results/control/control_values_slowdown6.yaml')
    assert script.parse_args(['campaign']).control_values.endswith('config/control_values.yaml')
    lr = script.parse_args(['local_remote'])
    default = load_testbed(os.path.join(script.report.WS, 'config', 'testbed.yaml')).robot_cpu.slowdown
    assert lr.slowdowns == [default, 2 * default] and lr.out.endswith('docs/results/local_remote')
    from cnr_benchmarks.session import slowdown_config, task_config
    cfg = slowdown_config(str(tmp_path), 6.5)
    assert load_testbed(os.path.join(cfg, 'testbed.yaml')).robot_cpu.cpus == pytest.approx(1 / 6.5)
    assert os.path.exists(os.path.join(cfg, 'migration.yaml'))
    other = slowdown_config(str(tmp_path / 'b'), 2.0, cfg)          # from another copy (bench_migration)
    assert load_testbed(os.path.join(other, 'testbed.yaml')).robot_cpu.cpus == pytest.approx(0.5)
    assert slowdown_config(str(tmp_path), 6.5, cfg) == cfg          # a copy given as its own source: kept
    assert os.path.exists(os.path.join(cfg, 'migration.yaml'))
    tasks = task_config(str(tmp_path / 't'))            # the task experiments' copy: the overlay set in it
    with open(os.path.join(tasks, 'migration.yaml')) as f:
        assert yaml.safe_load(f)['dormant'] == {'move_base': ['robot', 'cloud']}
    assert load_testbed(os.path.join(task_config(str(tmp_path / 't'), 6.5), 'testbed.yaml')).robot_cpu.cpus == \
        pytest.approx(1 / 6.5)
    from cnr_benchmarks import migration_bench
    assert migration_bench.main(['--slowdown', '0.5', '--out', str(tmp_path / 'm')]) == 2
    with pytest.raises(SystemExit):
        script.parse_args(['campaign', '--slowdown', '0.5'])
    with pytest.raises(SystemExit):
        script.parse_args(['local_remote', '--slowdowns', '3,x'])


def test_control_values_from_the_all_local_rows_of_a_results_file(tmp_path):
    """exp_control.sh --from-rows: CT/CB of the completed runs forced onload (or not forced); remote runs and
    unfinished runs are not control runs."""
    from cnr_benchmarks import campaign as script
    from network_monitor.core.evaluation import load_control_values
    rows = tmp_path / 'results.tsv'
    for i, (force, status, t, b) in enumerate([(ONLOAD, COMPLETED, 20.0, 0.003), (OFFLOAD, COMPLETED, 10.0, 0.001),
                                                (ONLOAD, COMPLETED, 22.0, 0.005), (ONLOAD, TIMED_OUT, 90.0, 0.02),
                                                ('', COMPLETED, 24.0, 0.004)]):
        append_result(str(rows), dict(id=f'r{i}', condition=f'c{i}', force=force, mission_status=status,
                                      t_task=t, b_task=b))
    cv = tmp_path / 'cv.yaml'
    args = script.parse_args(['control', '--from-rows', str(rows), '--out', str(tmp_path / 'out'),
                              '--control-values', str(cv)])
    assert script.control(args) == 0
    values = load_control_values(str(cv), 'corridor_round_trip')
    assert values.runs == 3 and values.ct_mean == pytest.approx(22.0) and values.cb_mean == pytest.approx(0.004)
    assert (tmp_path / 'out' / 'README.md').exists()
    args = script.parse_args(['control', '--from-rows', str(tmp_path / 'nope.tsv'), '--out', str(tmp_path / 'o2'),
                              '--control-values', str(tmp_path / 'cv2.yaml')])
    assert script.control(args) == 2 and not (tmp_path / 'cv2.yaml').exists()


def test_an_analysis_names_the_command_that_made_the_rows(tmp_path):
    """--analyse-only reports the campaign's own command (its command.txt), and itself beside it."""
    from cnr_benchmarks.campaign import parse_args
    from cnr_benchmarks.campaign_figures import _command
    args = parse_args(['analyse', '--out', str(tmp_path)])      # as exp_campaign.sh --analyse-only calls it
    assert _command(args) == f'`launch_scripts/exp_campaign.sh --analyse-only --out {tmp_path}`'
    (tmp_path / 'command.txt').write_text('launch_scripts/exp_campaign.sh --conditions 7 --seed 3\n')
    assert _command(args).startswith('`launch_scripts/exp_campaign.sh --conditions 7 --seed 3` (analysed by ')


def test_a_placement_not_made_is_evaluated_as_what_ran_and_a_split_one_is_not_learned(tmp_path):
    a = advisor(tmp_path)
    d, hosts, _ = a.begin('corridor_round_trip', 'corridor', GOOD, 0.0, force=OFFLOAD)
    a.placed(0.0, 0, {'move_base': 'robot'})                 # the migration to the cloud was rolled back
    assert a.running.placement == ONLOAD
    row, _ = a.finish(COMPLETED, 29.0, 0.0029, 1.7e9, learn=True)
    assert (row.decision, row.placement, row.label, a.learned) == (ONLOAD, 'move_base=robot', ONLOAD, True)
    rows, _ = TrainingSet(str(tmp_path / 'training'), 'corridor_round_trip', 'corridor').read()
    assert [(r.decision, r.placement) for r in rows] == [(ONLOAD, 'move_base=robot')]
    # mid-task: a re-decision whose migration failed leaves the placement (and the re-decider) where it was
    a = advisor(tmp_path, dwell=2.0, max_migrations=2, window=30.0, margin=0.8)
    a.begin('corridor_round_trip', 'corridor', GOOD, 100.0)              # cold start: offload
    a.placed(100.0, 1, {'move_base': 'cloud'})
    a.observe(BAD, 101.0)
    assert a.observe(BAD, 104.0)[0] == ONLOAD
    a.switched({'move_base': 'cloud'})
    assert a.running.placement == OFFLOAD and a.running.redecider.placement == OFFLOAD
    row, _ = a.finish(COMPLETED, 30.0, 0.003, 1.7e9 + 1, learn=True)
    assert row.placement == 'move_base=cloud' and row.decision == OFFLOAD


def test_a_split_placement_is_evaluated_but_not_learned(tmp_path):
    a = advisor(tmp_path)                                   # patrol places mfg and global_goal_manager
    write_control_values(a.cfg.control_values, dataclasses.replace(CONTROL, task='patrol'))
    a.begin('patrol', 'corridor', GOOD, 0.0, force=OFFLOAD)
    a.placed(0.0, 1, {'mfg': 'cloud', 'global_goal_manager': 'robot'})
    assert a.running.placement == 'split' and a.running.redecider is None
    row, _ = a.finish(COMPLETED, 29.0, 0.0029, 1.7e9, learn=True)
    assert row.placement == 'mfg=cloud,global_goal_manager=robot' and not a.learned
    assert TrainingSet(str(tmp_path / 'training'), 'patrol', 'corridor').read()[0] == []
