"""cnr_viz's ROS-free core: the markers built from plain data, the colour scale, the link map's zones, the rviz
view fitted to a grid; and the report's timeline (cnr_mission.core.timeline). No master."""
from __future__ import annotations

import json
import math
import os

import pytest

from cnr_maps.grid import MapcellGrid
from cnr_params import ConfigError, Section
from cnr_testbed.core.config import load_link_map
from cnr_viz.core.scene import ColorScale, Scene, VizConfig, build, link_zones, module_line, stale_keys
from cnr_viz.core.view import TopDownView, ViewConfig, fit, rviz_config

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(WS, 'config')


@pytest.fixture(scope='module')
def cfg() -> VizConfig:
    return VizConfig.from_section(Section.from_file(os.path.join(CONFIG, 'viz.yaml')))


@pytest.fixture
def grid() -> MapcellGrid:
    return MapcellGrid(min_x=0.0, min_y=-1.0, cell_size=1.0, cols=11, rows=2)


def test_the_shipped_config_loads_and_a_missing_field_is_named(cfg):
    assert cfg.frame_id == 'map' and cfg.rate > 0 and 'mfg' in cfg.modules
    data = Section.from_file(os.path.join(CONFIG, 'viz.yaml')).data
    del data['viz']['colors']['hotspot']
    with pytest.raises(ConfigError, match='colors.hotspot'):
        VizConfig.from_section(Section(data, 'viz.yaml'))


def test_colour_scale_marks_ambient_and_threshold(cfg):
    s = ColorScale.of(cfg, 22.0, 24.0)
    assert s.color(22.0) == cfg.colors['ambient']
    assert s.color(24.0) == cfg.colors['hot'] and s.color(40.0) == cfg.colors['hot']
    assert s.color(s.low) == cfg.colors['cool'] and s.color(0.0) == cfg.colors['cool']
    mid = s.color(23.0)
    assert all(min(a, b) <= m <= max(a, b) for m, a, b in zip(mid, cfg.colors['ambient'], cfg.colors['hot']))


def test_link_zones_of_the_corridor_map_mark_the_dead_zone_between_the_ends(grid):
    lm = load_link_map(os.path.join(CONFIG, 'link_map_corridor.yaml'))
    regions = [(r.name, r.x_min, r.x_max, r.y_min, r.y_max, r.conditions.outage) for r in lm.regions]
    zones = link_zones(regions, lm.default.outage, (grid.min_x, grid.min_y, grid.max_x, grid.max_y))
    by_name = {z.name: z for z in zones}
    assert set(by_name) == {'left_end', 'right_end', 'default'}
    dead = by_name['default']
    assert dead.dead and (dead.x_min, dead.x_max, dead.y_min, dead.y_max) == (1.5, 10.0, -1.0, 1.0)
    assert not by_name['left_end'].dead and (by_name['left_end'].x_min, by_name['left_end'].x_max) == (0.0, 1.5)
    assert (by_name['right_end'].x_min, by_name['right_end'].x_max) == (10.0, 11.0)
    assert math.isclose(sum((z.x_max - z.x_min) * (z.y_max - z.y_min) for z in zones), 22.0)


def test_build_shows_cells_search_goals_hotspot_and_where_modules_run(cfg, grid):
    scale = ColorScale.of(cfg, 22.0, 24.0)
    scene = Scene(grid=grid, means={3: 22.0}, latest={19: 31.0}, mode='SEARCH', mfg_goal=20, investigation=19,
                  checked=(8, 18), hotspot=(19, 30.5), global_goal=(4.5, 0.5), robot=(8.4, 0.3, 0.5),
                  hosts={'mfg': ('cloud', 3)}, placement_source='migration_manager', link=(True, 0.0042, 12.5))
    specs = build(scene, cfg, scale)
    keys = {s.key for s in specs}
    assert len(keys) == len(specs), 'one (ns, id) per marker'
    cells = next(s for s in specs if s.ns == 'mapcells')
    assert len(cells.points) == len(cells.colors) == 22
    assert cells.colors[19] == cfg.colors['hot'] and cells.colors[3] == cfg.colors['ambient']
    assert cells.colors[0] == cfg.colors['unvisited']
    hot = [s for s in specs if s.ns == 'hotspot']
    assert {s.type for s in hot} == {'LINE_LIST', 'CYLINDER', 'TEXT_VIEW_FACING'}
    assert all(s.color == cfg.colors['hotspot'] for s in hot)
    cyl = next(s for s in hot if s.type == 'CYLINDER')
    assert cyl.position[:2] == (8.5, 0.5)
    texts = [s.text for s in specs if s.ns == 'placement']
    assert any(t.startswith('mfg: cloud (term 3)') and 'RTT 4.2 ms' in t and 'R_bw 12.5' in t for t in texts)
    assert any('migration_manager' in t and 'SEARCH' in t for t in texts)
    assert ('goals', 0) in keys and ('goals', 1) in keys and ('robot', 0) in keys
    assert {('search', 0), ('search', 1)} <= keys
    labels = [s.text for s in specs if s.ns == 'scale']
    assert 'ambient 22.0 degC' in labels and 'threshold 24.0 degC' in labels


def test_latest_temperature_wins_over_the_mean_and_gone_markers_are_deleted(cfg, grid):
    scale = ColorScale.of(cfg, 22.0, 24.0)
    scene = Scene(grid=grid, means={5: 30.0}, latest={5: 21.0}, mfg_goal=5)
    assert scene.cell_temperature(5) == 21.0 and math.isnan(scene.cell_temperature(6))
    before = build(scene, cfg, scale)
    scene.mfg_goal = -1
    after = build(scene, cfg, scale)
    assert stale_keys([s.key for s in before], after) == [('goals', 1)]


def test_module_line_when_the_link_is_down_and_without_a_link():
    assert module_line('mfg', 'robot', 0, None) == 'mfg: robot'
    assert module_line('mfg', '', 2, (False, math.nan, math.nan)) == 'mfg: nowhere (migrating) (term 2)  link DOWN'


def test_the_view_fits_the_grid_and_projects_points(grid):
    cfg = ViewConfig((900.0, 600.0), (1.0, 3.0), 0.5, 'RViz', 60.0, 3)
    v = fit(grid, cfg)
    assert (v.x, v.y) == (5.5, 0.5) and math.isclose(v.scale, min(900 / 13, 600 / 8))
    col, row = v.project(5.5, 0.5, cfg.panel)
    assert (col, row) == (450.0, 300.0)
    col, row = TopDownView(0.0, 0.0, 10.0).project(1.0, 2.0, (100, 100))
    assert (col, row) == (60.0, 30.0)


def test_the_shipped_rviz_config_gets_the_fitted_view():
    import yaml
    with open(os.path.join(CONFIG, 'mission.rviz')) as f:
        text = rviz_config(f.read(), TopDownView(1.25, -2.5, 42.0))
    doc = yaml.safe_load(text)
    cur = doc['Visualization Manager']['Views']['Current']
    assert (cur['X'], cur['Y'], cur['Scale']) == (1.25, -2.5, 42.0)
    topics = {d.get('Topic') or d.get('Marker Topic') for d in doc['Visualization Manager']['Displays']}
    assert {'/map', '/scan', '/camera/depth/points', '/move_base/NavfnROS/plan', '/viz_markers/markers',
            '/move_base/local_costmap/footprint'} <= topics


def test_the_timeline_is_drawn_from_a_report_folder(tmp_path):
    from cnr_mission.core.timeline import from_report, write_timeline
    (tmp_path / 'placement.tsv').write_text('time\tmodule\thost\tterm\n0.0\tmfg\trobot\t1\n10.0\tmfg\t-\t1\n'
                                            '10.5\tmfg\tcloud\t2\n0.0\tglobal_goal_manager\trobot\t1\n')
    (tmp_path / 'network_profile.tsv').write_text('time\talive\trtt\trtt_spread\tloss\tc_bw\ta_bw\tr_bw\n'
                                                  '1\t1\t0.004\t0\t0\t1\t1\t1\n2\t0\tnan\tnan\tnan\t1\t1\t1\n'
                                                  '5\t1\t0.005\t0\t0\t1\t1\t1\n')
    (tmp_path / 'measurements.tsv').write_text('measurement\ttime\tx\ty\ttemperature\tcell\trow\tcol\tpose_time\n'
                                               '1\t100.5\t0\t0\t22\t0\t0\t0\t100.5\n'
                                               '2\t101.2\t0\t0\t22\t0\t0\t0\t101.2\n')
    (tmp_path / 'decisions.tsv').write_text('time\tevent\tdecision\n0.5\tdecided\toffload\n')
    summary = dict(scenario='corridor', placement='all_robot', sim_time_start=100.0, sim_time_total=20.0,
                   sim_time_to_find=15.0, migrations=[dict(time=10.0, module='mfg', source='robot', target='cloud',
                                                           outcome='done')])
    tl = from_report(str(tmp_path), summary)
    assert tl.hosts['mfg'] == [(0.0, 'robot', 1), (10.0, '-', 1), (10.5, 'cloud', 2)]
    assert tl.down == [(2.0, 5.0)]
    assert tl.measurement_times == pytest.approx([0.5, 1.2])
    assert tl.decisions == [(0.5, 'decided: offload')] and tl.migrations[0][:2] == (10.0, 'mfg')
    path = write_timeline(str(tmp_path), summary)
    assert os.path.getsize(path) > 10000
    one = from_report(str(tmp_path / 'nothing'), dict(scenario='corridor', placement='one_master', sim_time_total=5.0))
    assert one.hosts == {'every module': [(0.0, 'robot', 0)]} and not one.rtt
    (tmp_path / 'nothing').mkdir()
    write_timeline(str(tmp_path / 'nothing'), json.loads(json.dumps(dict(sim_time_total=5.0))))


def test_view_without_a_display_says_why_and_the_bag_topics_come_from_the_config(tmp_path):
    from cnr_viz import viewer
    assert viewer.display_problem('') == 'no display ($DISPLAY is not set)'
    argv = viewer.record_argv(CONFIG, str(tmp_path))
    assert argv[:5] == ['rosbag', 'record', '--quiet', '-O', str(tmp_path / 'mission.bag')]
    assert {'/viz_markers/markers', '/merged_measurements', '/migration_manager/placement', '/migration_manager/events',
            '/network_monitor/robot/network_profile', '/odom', '/tf', '/scan'} <= set(argv[5:])
    path, view, cfg = viewer.write_rviz_config(CONFIG, os.path.join(CONFIG, 'scenarios', 'corridor.yaml'),
                                               str(tmp_path))
    assert os.path.dirname(path) == str(tmp_path) and (view.x, view.y) == (5.5, 0.0 + cfg.center_shift)


def test_the_timeline_is_redrawn_with_a_fixed_placements_hosts(tmp_path):
    from cnr_mission.core.timeline import TIMELINE, from_report, redraw_timeline
    summary = dict(scenario='corridor', placement='paper_normal', sim_time_total=5.0,
                   two_host=dict(hosts={'mfg': 'cloud', 'move_base': 'robot'}))
    assert from_report(str(tmp_path), summary).hosts == {'mfg': [(0.0, 'cloud', 0)], 'move_base': [(0.0, 'robot', 0)]}
    redraw_timeline(str(tmp_path))                     # no summary: nothing drawn
    assert not (tmp_path / TIMELINE).exists()
    (tmp_path / 'summary.json').write_text(json.dumps(summary))
    redraw_timeline(str(tmp_path))
    assert (tmp_path / TIMELINE).stat().st_size > 10000


def test_a_bad_viz_config_is_named_before_anything_starts(tmp_path):
    import shutil
    import yaml
    from cnr_viz.viewer import check_config
    check_config(CONFIG)
    shutil.copy(os.path.join(CONFIG, 'viz.yaml'), tmp_path / 'viz.yaml')
    data = yaml.safe_load((tmp_path / 'viz.yaml').read_text())
    data['viz']['record']['topics'] = ['scan']
    (tmp_path / 'viz.yaml').write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r'viz.yaml: viz.record.topics: expected a list of topic names'):
        check_config(str(tmp_path))
