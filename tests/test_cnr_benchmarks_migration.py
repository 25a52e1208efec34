"""bench_migration's analysis: consumer-side downtime from probe rows, stray outputs, the grouped table."""
import math

from cnr_benchmarks.core.migration import ProbeRow, group_results, handover_downtime, handover_gap, stray_outputs


def rows(spec):
    return [ProbeRow(t, topic, inst, ok) for t, topic, inst, ok in spec]


def test_gap_is_last_old_to_first_new_on_the_consumer():
    r = rows([(9.0, '/mfg/activity', 'mfg@robot', True), (10.0, '/mfg/activity', 'mfg@robot', True),
              (10.4, '/mfg/activity', 'mfg@cloud', True), (10.9, '/mfg/activity', 'mfg@cloud', True)])
    assert math.isclose(handover_gap(r, 'mfg', 'robot', 'cloud', 9.5, 10.5), 0.4)
    assert stray_outputs(r, 'mfg', 'robot', 'cloud', 9.5, 10.5) == 0
    r.append(ProbeRow(10.5, '/mfg/activity', 'mfg@robot', True))
    assert stray_outputs(r, 'mfg', 'robot', 'cloud', 9.5, 10.5) == 1
    assert handover_gap(r[:2], 'mfg', 'robot', 'cloud', 9.5, 10.5) is None        # the new one never spoke


def test_gap_of_service_answers_is_the_longest_silence():
    r = rows([(t / 20, 'next_goal', '', True) for t in range(100)] +
             [(5.0 + t / 20, 'next_goal', '', True) for t in range(1, 40)])
    r = [x for x in r if not 3.0 < x.time < 3.3]
    assert math.isclose(handover_gap(r, 'global_goal_manager', 'robot', 'cloud', 2.5, 3.5), 0.3, abs_tol=1e-9)


def test_table_groups_and_percentiles():
    res = [dict(rtt='50', module='mfg', mode='cold', outcome='done', consumer_gap=str(g), manager_downtime='0.1')
           for g in (0.1, 0.2, 0.3, 0.4)] + [dict(rtt='50', module='mfg', mode='cold', outcome='rolled_back',
                                                    consumer_gap='', manager_downtime='')]
    res[0]['downtime'] = '0.05'
    (g,) = group_results(res, ('rtt', 'module', 'mode'))
    row = dict(zip(('rtt', 'module', 'mode') + g.HEADER, g.row()))
    assert row['done'] == '4/5' and row['gaps'] == '4' and row['gap p50'] == '250' and row['gap max'] == '400'
    assert row['downtime p50'] == '50' and row['manager p50'] == '100'


def test_downtime_runs_from_the_old_instance_closing_its_outputs_to_the_new_one_s_first_output():
    r = rows([(9.0, '/mfg/activity', 'mfg@robot', True), (9.9, 'frozen', 'mfg@robot', True),
              (9.95, '/mfg/activity', 'mfg@robot', True),          # in flight when it froze: not the new one
              (10.02, '/mfg/activity', 'mfg@cloud', True), (11.0, '/mfg/activity', 'mfg@cloud', True)])
    assert math.isclose(handover_downtime(r, 'mfg', 'robot', 'cloud', 9.8, 10.1), 0.12)
    assert math.isclose(handover_gap(r, 'mfg', 'robot', 'cloud', 9.8, 10.1), 0.07)
    assert handover_downtime(r[:1] + r[2:], 'mfg', 'robot', 'cloud', 9.8, 10.1) is None    # not frozen: failover
    gg = rows([(9.0, 'next_goal', '', True), (9.5, 'frozen', 'global_goal_manager@cloud', True),
               (9.55, 'next_goal', '', False), (9.65, 'next_goal', '', True)])
    assert math.isclose(handover_downtime(gg, 'global_goal_manager', 'cloud', 'robot', 9.4, 9.7), 0.15)


def test_a_move_base_gap_across_a_finished_goal_is_not_a_hand_over():
    drive = [(9.0 + t / 10, '/mobile_base/commands/velocity', 'move_base@robot', True) for t in range(5)]
    r = rows(drive + [(9.45, '/move_base/result', '3', True), (12.0, '/mobile_base/commands/velocity',
                                                               'move_base@cloud', True)])
    assert handover_gap(r, 'move_base', 'robot', 'cloud', 9.3, 9.6) is None
    r = rows(drive + [(9.6, '/mobile_base/commands/velocity', 'move_base@cloud', True)])
    assert math.isclose(handover_gap(r, 'move_base', 'robot', 'cloud', 9.3, 9.6), 0.2)


def test_output_flowing_and_period(tmp_path):
    from cnr_benchmarks.core.migration import output_flowing, output_period, read_probe
    path = tmp_path / 'probe.tsv'
    lines = ['time\ttopic\tinstance\tok'] + [f'{100 + t / 3:.6f}\t/mapcell_measurements\tlocal_mapcell_manager@robot\t1'
                                            for t in range(300)]
    path.write_text('\n'.join(lines) + '\n1\t/mapcell')             # a line still being written
    r = read_probe(str(path), tail_bytes=2000)
    assert 10 < len(r) < 300 and r[-1].time == read_probe(str(path))[-1].time
    assert output_flowing(r, 'local_mapcell_manager', r[-1].time + 0.2, 0.5)
    assert not output_flowing(r, 'local_mapcell_manager', r[-1].time + 1.0, 0.5)
    assert math.isclose(output_period(read_probe(str(path)), 'local_mapcell_manager'), 1 / 3, rel_tol=1e-3)


def test_a_store_s_downtime_is_the_longest_a_measurement_waited_for_it_across_the_hand_over():
    m, out = '/merged_measurements', '/mapcell_measurements'
    old, new = 'local_mapcell_manager@robot', 'local_mapcell_manager@cloud'
    base = [ProbeRow(9.0, m, '-', True, 100.0), ProbeRow(9.01, out, old, True, 100.0),
            ProbeRow(9.5, 'frozen', old, True)]
    # a measurement arrives during the hand-over and is stored by the new instance 0.2 s later
    waited = base + [ProbeRow(9.6, m, '-', True, 100.3), ProbeRow(9.8, out, new, True, 100.3 + 1e-9),
                     ProbeRow(10.0, m, '-', True, 100.6), ProbeRow(10.01, out, new, True, 100.6)]
    assert math.isclose(handover_downtime(waited, 'local_mapcell_manager', 'robot', 'cloud', 9.4, 9.9), 0.2)
    # none arrives until the new instance is active: the store was never waited for
    idle = base + [ProbeRow(10.0, m, '-', True, 100.6), ProbeRow(10.01, out, new, True, 100.6)]
    assert math.isclose(handover_downtime(idle, 'local_mapcell_manager', 'robot', 'cloud', 9.4, 9.9), 0.01)
    assert math.isclose(handover_gap(idle, 'local_mapcell_manager', 'robot', 'cloud', 9.4, 9.9), 1.0)
