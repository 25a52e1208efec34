"""The mission in rviz, for real: ``run_mission.sh --view --record`` on a short single-master corridor mission
under Xvfb (Debian's rviz with Mesa's software GL). The report holds rviz's last view (``view.png``: the hotspot's
colour where the hotspot cell lands in rviz's render panel, the mapcells' temperature colours around it), the
timeline and ``mission.bag``; ``rosbag play`` of the bag publishes the same markers again, hotspot included, and
drives rviz to the same view.

Skipped, saying why, when rviz, Xvfb or python3-xlib is missing (``launch_scripts/setup.sh`` installs them)."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess

import pytest

from cnr_harness import RosMaster, free_port, stop_process, wait_until

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MISSING = [what for what, ok in (('rviz', shutil.which('rviz')), ('Xvfb', shutil.which('Xvfb')),
                                  ('python3-xlib', importlib.util.find_spec('Xlib'))) if not ok]
pytestmark = pytest.mark.skipif(bool(MISSING), reason=f'{", ".join(MISSING)} missing (Debian packages rviz, xvfb, '
                                                      'python3-xlib: launch_scripts/setup.sh installs them)')
HOTSPOT = (200, 80, 200)      # magenta: red and blue above, green below (config/viz.yaml colors.hotspot)
TITLE = ' - RViz'             # in rviz's main window's title (config/viz.yaml view.window_title)


@pytest.fixture(scope='module')
def xvfb():
    """A virtual X display of its own (Xvfb picks a free number and writes it to the pipe)."""
    read, write = os.pipe()
    proc = subprocess.Popen(['Xvfb', '-displayfd', str(write), '-screen', '0', '1280x800x24', '-nolisten', 'tcp'],
                            pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    os.close(write)
    with os.fdopen(read) as f:
        number = f.readline().strip()
    assert number, 'Xvfb did not start'
    try:
        yield f':{number}'
    finally:
        stop_process(proc)


@pytest.fixture(scope='module')
def viewed_mission(xvfb, tmp_path_factory):
    """The corridor mission at 10x real time with --view and --record: (exit status, output, report folder)."""
    report = str(tmp_path_factory.mktemp('viz') / 'report')
    env = dict(os.environ, DISPLAY=xvfb, ROS_MASTER_URI=f'http://127.0.0.1:{free_port()}')
    out = subprocess.run([os.path.join(WS, 'launch_scripts', 'run_mission.sh'), '--single-master', '--view',
                          '--record', '--rtf', '10', '--report-dir', report], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, timeout=540)     # within the test timeout
    return out.returncode, out.stdout, report


def test_the_view_shows_mapcells_hotspot_and_placement(viewed_mission, workspace):
    from PIL import Image
    from cnr_maps.grid import MapcellGrid
    from cnr_params import Section
    from cnr_viz.core.view import ViewConfig, fit
    import numpy as np
    status, output, report = viewed_mission
    assert status == 0, output[-3000:]
    assert '--view: rviz on' in output and 'the last view saved as' in output, output[-3000:]
    with open(os.path.join(report, 'summary.json')) as f:
        summary = json.load(f)
    img = np.asarray(Image.open(os.path.join(report, 'view.png')).convert('RGB')).astype(int)
    with open(os.path.join(report, 'logs', 'rviz_panel.json')) as f:
        px, py, pw, ph = json.load(f)
    # where the hotspot cell's centre lands in the render panel (rviz's top-down view as the report's config set it)
    scenario = os.path.join(workspace, 'config', 'scenarios', 'corridor.yaml')
    grid = MapcellGrid.from_section(Section.from_file(scenario).section('mapcells'))
    view = fit(grid, ViewConfig.from_section(Section.from_file(os.path.join(workspace, 'config', 'viz.yaml'))))
    h = summary['hotspot']
    col, row = view.project(h['x'], h['y'], (pw, ph))
    col, row = px + col, py + row
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    magenta = (r > HOTSPOT[0]) & (g < HOTSPOT[1]) & (b > HOTSPOT[2])
    ys, xs = np.nonzero(magenta)
    assert len(xs) > 50, 'no hotspot colour in the view'
    near = (abs(xs - col) < view.scale * grid.cell_size / 2) & (abs(ys - row) < view.scale * grid.cell_size / 2)
    assert near.sum() > 0.5 * view.scale ** 2 * 0.1, f'hotspot colour not at the hotspot cell ({col:.0f}, {row:.0f})'
    # the mapcells' colours: hot cells (red) next to it, cells near the ambient (white-ish) elsewhere in the grid
    band = img[int(row - view.scale * 1.5):int(row + view.scale * 1.5), px:px + pw]
    red = (band[..., 0] > 200) & (band[..., 1] < 60) & (band[..., 2] < 60)
    assert red.sum() > view.scale ** 2 * 0.3, 'no hot mapcell colour'
    # the placement texts (white) above the grid
    _, top = view.project(0.0, grid.max_y + 3.0, (pw, ph))
    _, bottom = view.project(0.0, grid.max_y + 0.2, (pw, ph))
    above = img[py + max(int(top), 0):py + int(bottom), px:px + pw]
    assert ((above > 240).all(axis=-1)).sum() > 200, 'no placement text above the grid'
    assert os.path.getsize(os.path.join(report, 'timeline.png')) > 10000


def _hotspot_pixels(path: str) -> int:
    from PIL import Image
    import numpy as np
    img = np.asarray(Image.open(path).convert('RGB')).astype(int)
    return int(((img[..., 0] > HOTSPOT[0]) & (img[..., 1] < HOTSPOT[1]) & (img[..., 2] > HOTSPOT[2])).sum())


def test_the_recorded_bag_replays_into_the_same_view(viewed_mission, xvfb, tmp_path):
    """The bag holds the mission's topics and the markers (the hotspot's among them); rviz with the report's config
    on a fresh master of its own, then ``rosbag play --clock`` of the bag: rviz shows the hotspot again."""
    import rosbag
    from cnr_params import Section
    from cnr_viz.core.view import ViewConfig
    from cnr_viz.screenshot import grab, window_present
    from cnr_viz.viewer import open_rviz
    status, output, report = viewed_mission
    assert status == 0, output[-3000:]
    view = ViewConfig.from_section(Section.from_file(os.path.join(WS, 'config', 'viz.yaml')))
    path = os.path.join(report, 'mission.bag')
    with rosbag.Bag(path) as bag:
        topics = set(bag.get_type_and_topic_info().topics)
        namespaces = {mk.ns for _, msg, _ in bag.read_messages(topics=['/viz_markers/markers']) for mk in msg.markers}
        lines = {mk.text for _, msg, _ in bag.read_messages(topics=['/viz_markers/markers']) for mk in msg.markers
                 if mk.ns == 'placement'}
    assert {'/viz_markers/markers', '/merged_measurements', '/odom', '/tf', '/scan', '/hotspot', '/map',
            '/cell_states', '/battery_state'} <= topics
    assert {'mapcells', 'scale', 'hotspot', 'placement', 'robot'} <= namespaces
    assert 'mfg: robot' in lines
    master = RosMaster(log_dir=os.path.join(WS, 'build', 'test_logs'), use_sim_time=True, caller='/test_cnr_viz')
    try:
        # rviz shows its window once its displays are created (and subscribed); started again if it crashes first
        rviz = open_rviz(lambda: master.run(['rviz', '-d', os.path.join(report, 'logs', 'mission.rviz')],
                                            'rviz_replay', env={'DISPLAY': xvfb}), xvfb, view)
        assert rviz is not None, 'rviz ended before its window showed, every time'
        wait_until(lambda: window_present(xvfb, TITLE), 180, "rviz's window", rviz)
        master.run(['rosbag', 'play', '--clock', '-r', '10', path], 'rosbag_play')
        shot = str(tmp_path / 'replay.png')
        wait_until(lambda: grab(xvfb, TITLE, shot)[2] and _hotspot_pixels(shot) > 50, 180,
                   'the hotspot in the replayed view', rviz, interval=0.5)
    finally:
        master.stop()
