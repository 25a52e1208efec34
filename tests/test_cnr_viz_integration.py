"""The mission in rviz, for real: ``run_mission.sh --view --record`` on a short single-master corridor mission
under Xvfb (Debian's rviz with Mesa's software GL). The report holds rviz's last view (``view.png``: the hotspot's
colour where the hotspot cell lands in rviz's render panel, the mapcells' temperature colours around it), the
timeline and ``mission.bag``; ``rosbag play`` of the bag publishes the same markers again, hotspot included.

Skipped, saying why, when rviz, Xvfb or python3-xlib is missing (``launch_scripts/setup.sh`` installs them)."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess

import pytest

from cnr_harness import free_port, stop_process, wait_until

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MISSING = [what for what, ok in (('rviz', shutil.which('rviz')), ('Xvfb', shutil.which('Xvfb')),
                                  ('python3-xlib', importlib.util.find_spec('Xlib'))) if not ok]
pytestmark = pytest.mark.skipif(bool(MISSING), reason=f'{", ".join(MISSING)} missing (Debian packages rviz, xvfb, '
                                                      'python3-xlib: launch_scripts/setup.sh installs them)')
HOTSPOT = (200, 80, 200)      # magenta: red and blue above, green below (config/viz.yaml colors.hotspot)


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
                         stderr=subprocess.STDOUT, text=True, timeout=600)
    return out.returncode, out.stdout, report


def test_the_view_shows_mapcells_hotspot_and_placement(viewed_mission, workspace):
    from PIL import Image
    from cnr_maps.grid import MapcellGrid
    from cnr_params import Section
    from cnr_viz.core.view import ViewConfig, fit
    import numpy as np
    status, output, report = viewed_mission
    assert status == 0, output[-3000:]
    assert '--view: rviz on' in output and 'view.png' in output
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


def test_the_recorded_bag_replays_the_markers(viewed_mission, ros):
    import rospy
    from visualization_msgs.msg import MarkerArray
    status, output, report = viewed_mission
    assert status == 0, output[-3000:]
    bag = os.path.join(report, 'mission.bag')
    info = subprocess.run(['rosbag', 'info', '--yaml', '--key=topics', bag], stdout=subprocess.PIPE, text=True,
                          check=True).stdout
    for topic in ('/viz_markers/markers', '/merged_measurements', '/odom', '/tf', '/scan', '/hotspot'):
        assert f'topic: {topic}' in info, f'{topic} not recorded'
    seen = []
    sub = rospy.Subscriber('/viz_markers/markers', MarkerArray,
                           lambda m: seen.append({(mk.ns, mk.text) for mk in m.markers}), queue_size=50)
    play = ros.master.run(['rosbag', 'play', '--clock', '-r', '20', '--topics', '/viz_markers/markers', '--bags', bag],
                          'rosbag_play')
    try:
        wait_until(lambda: any(ns == 'hotspot' for s in seen for ns, _ in s), 120, 'the hotspot marker from the bag')
    finally:
        sub.unregister()
        ros.master.stop_child(play)
    assert any(ns == 'mapcells' for s in seen for ns, _ in s)
    assert any(ns == 'placement' and text.startswith('mfg: robot') for s in seen for ns, text in s)
