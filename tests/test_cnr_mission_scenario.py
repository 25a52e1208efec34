"""The scenario check (cnr_mission check_scenario) without a master: the repository's scenarios pass; each bad
field gives one line `FILE: field: problem` and exit status 2, no traceback."""
import copy
import os
import subprocess

import numpy as np
import pytest
import yaml

from cnr_maps.mapio import load_map
from cnr_mission.core.scenario import validate_scenario
from cnr_params import ConfigError


@pytest.fixture(scope='module')
def dirs(workspace):
    return os.path.join(workspace, 'config'), os.path.join(workspace, 'maps')


@pytest.fixture(scope='module')
def corridor(dirs):
    with open(os.path.join(dirs[0], 'scenarios', 'corridor.yaml')) as f:
        return yaml.safe_load(f)


def check(path, dirs):
    return subprocess.run(['rosrun', 'cnr_mission', 'check_scenario', str(path), '--config-dir', dirs[0],
                           '--maps-dir', dirs[1]], capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize('name', ['corridor', 'datacenter'])
def test_repository_scenarios_pass_and_print_one_line(name, dirs):
    path = os.path.join(dirs[0], 'scenarios', f'{name}.yaml')
    sc = validate_scenario(path, *dirs)
    assert sc.name == name and sc.mfg.neighbourhood == 4 and sc.grid.cols > 1
    r = check(path, dirs)
    assert r.returncode == 0, r.stderr
    out_name, map_file, x, y, a = r.stdout.strip().split(' ')
    assert out_name == name and os.path.isfile(map_file) and map_file.endswith('.yaml')
    assert (float(x), float(y), float(a)) == (sc.start.x, sc.start.y, sc.start.yaw)
    assert r.stderr == ''


def occupied_point(map_file):
    m = load_map(map_file)
    rows, cols = np.nonzero(m.data == 100)
    x, y = m.cell_to_world(rows[len(rows) // 2], cols[len(cols) // 2])
    return float(x), float(y)


def set_in(d, dotted, value):
    keys = dotted.split('.')
    for k in keys[:-1]:
        d = d[int(k)] if isinstance(d, list) else d[k]
    if value is DELETE:
        del d[keys[-1]]
    else:
        d[keys[-1]] = value


DELETE = object()
CASES = [
    ('bad_peak', 'temperature_field.sources.0.peak', 'hot', "temperature_field.sources[0].peak: expected a number"),
    ('grid_outside', 'mapcells.cols', 40, 'mapcells: grid [0, 40]'),
    ('start_in_obstacle', 'scenario.start', 'OCCUPIED', 'scenario.start: '),
    ('bad_neighbourhood', 'mfg.neighbourhood', 6, 'mfg.neighbourhood: must be 4 or 8, got 6'),
    ('missing_timeout', 'mission.timeout', DELETE, 'mission.timeout: missing'),
    ('missing_policy', 'global_goal_manager.policy', DELETE, 'global_goal_manager.policy: missing'),
    ('bad_mode', 'mfg.threshold.mode', 'magic', "mfg.threshold.mode: unknown value 'magic'"),
    ('map_missing', 'scenario.map', 'nowhere.yaml', 'scenario.map: file not found: '),
    ('radius_zero', 'temperature_field.sources.1.radius', 0.0, 'temperature_field.sources[1].radius: must be > 0'),
    ('ambient_text', 'temperature_field.ambient', 'warm', 'temperature_field.ambient: expected a number'),
]


@pytest.mark.parametrize('label, field, value, expected', CASES, ids=[c[0] for c in CASES])
def test_bad_scenario_one_line_exit_2(label, field, value, expected, corridor, dirs, tmp_path):
    data = copy.deepcopy(corridor)
    if value == 'OCCUPIED':
        x, y = occupied_point(os.path.join(dirs[1], data['scenario']['map']))
        value = [x, y, 0.0]
        expected += f'({x:g}, {y:g}) is on an occupied map cell'
    set_in(data, field, value)
    path = tmp_path / f'{label}.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as err:
        validate_scenario(str(path), *dirs)
    assert str(err.value).startswith(f'{path}: ') and expected in str(err.value), str(err.value)
    r = check(path, dirs)
    assert r.returncode == 2 and r.stdout == ''
    lines = r.stderr.splitlines()
    assert lines == [str(err.value)], r.stderr


def test_unreadable_scenario_file(dirs, tmp_path):
    r = check(tmp_path / 'absent.yaml', dirs)
    assert r.returncode == 2 and r.stderr.strip() == f'{tmp_path / "absent.yaml"}: file not found'
