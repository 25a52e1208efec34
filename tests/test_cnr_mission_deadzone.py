"""The dead-zone experiment's analysis (cnr_benchmarks.core.deadzone): runs read from report folders, table, plot."""
import json
import os

from cnr_maps.measurements import Measurement, write_tsv
from cnr_benchmarks.core.deadzone import load_run, run_folder, write_outputs


def fake_run(out, mode, i, found, t, n, idle, temps):
    folder = run_folder(out, mode, i)
    os.makedirs(folder)
    summary = dict(found=found, sim_time_to_find=t if found else None, measurements_to_hotspot=n if found else None,
                   mfg_activity=dict(longest_idle=idle, longest_input_gap=idle, goal_wait_longest=0.01),
                   two_host=dict(wall_time_total=120.0))
    with open(os.path.join(folder, 'summary.json'), 'w') as f:
        json.dump(summary, f)
    write_tsv(os.path.join(folder, 'measurements.tsv'),
              [Measurement(k, k / 3.0, 0.0, 0.0, v, 0, 0, 0, k / 3.0) for k, v in enumerate(temps)])
    return load_run(folder, mode, i)


def test_table_and_plot(tmp_path):
    out = str(tmp_path)
    runs = [fake_run(out, 'network_aware', i, True, 80.0 + i, 240 + i, 0.4, [22.0, 25.0, 30.0]) for i in (1, 2, 3)]
    runs += [fake_run(out, 'normal_uplink', i, True, 115.0 + i, 345 + i, 25.0, [22.0, 23.0]) for i in (1, 2, 3)]
    runs += [fake_run(out, 'normal', i, False, None, None, 150.0, [22.0]) for i in (1, 2)]
    assert load_run(os.path.join(out, 'missing'), 'normal', 9) is None
    md = write_outputs(out, runs, 'exp_deadzone.sh --runs 3')
    assert '| network_aware | paper_network_aware, link_map_corridor.yaml | 3 (3) | 82.0' in md
    assert '| normal | paper_normal, link_map_corridor.yaml | 2 (0) | - | - | 150.00' in md
    assert 'normal_uplink − network_aware, runs that found the hotspot): 35.0 s and 105 measurements' in md
    assert 'normal: no run found the hotspot' in md
    assert os.path.getsize(os.path.join(out, 'deadzone.png')) > 10000
    with open(os.path.join(out, 'runs.tsv')) as f:
        assert len(f.readlines()) == 1 + len(runs)
