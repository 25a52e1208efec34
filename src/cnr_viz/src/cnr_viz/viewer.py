"""What ``run_mission.sh --view`` and ``--record`` start beside the mission (no ROS imports: processes only).

* :func:`display_problem`: why rviz cannot be opened here ('' when it can): no ``$DISPLAY``, no rviz, or a
  display that does not answer;
* :func:`write_rviz_config`: ``config/mission.rviz`` centred on the scenario's mapcell grid, written into the
  report folder (the view the screenshot shows);
* :func:`rviz_argv`, :func:`record_argv`: the commands (Debian's rviz, ``rosbag record`` of
  ``viz.record.topics`` into the report);
* :func:`screenshot`: rviz's window as ``view.png`` in the report.
"""
from __future__ import annotations

import json
import os
import shutil
from typing import Any, Callable, List, Optional, Tuple

from cnr_maps.grid import MapcellGrid
from cnr_params import Section
from cnr_viz.core.view import TopDownView, ViewConfig, fit, rviz_config

RVIZ_CONFIG = 'mission.rviz'
SCREENSHOT = 'view.png'
BAG = 'mission.bag'
PANEL = 'rviz_panel.json'


def check_config(config_dir: str) -> None:
    """``config/viz.yaml`` as a whole (the node's settings, the view, the bag's topics), before anything starts:
    a ConfigError naming file and field."""
    from cnr_viz.core.scene import VizConfig
    sec = Section.from_file(os.path.join(config_dir, 'viz.yaml'))
    VizConfig.from_section(sec)
    ViewConfig.from_section(sec)
    record_topics(config_dir)


def display_problem(display: str) -> str:
    """'' when rviz can open a window on ``display``, else why not (one line)."""
    if not display:
        return 'no display ($DISPLAY is not set)'
    if shutil.which('rviz') is None:
        return 'rviz is not installed (Debian package rviz; launch_scripts/setup.sh installs it)'
    from cnr_viz.screenshot import window_present
    if window_present(display, '') is None:
        return f'the display {display} does not answer'
    return ''


def write_rviz_config(config_dir: str, scenario_file: str, out_dir: str) -> Tuple[str, TopDownView, ViewConfig]:
    """``config/mission.rviz`` with its view fitted to the scenario's grid, as ``out_dir/mission.rviz``."""
    cfg = ViewConfig.from_section(Section.from_file(os.path.join(config_dir, 'viz.yaml')))
    grid = MapcellGrid.from_section(Section.from_file(scenario_file).section('mapcells'))
    view = fit(grid, cfg)
    with open(os.path.join(config_dir, RVIZ_CONFIG)) as f:
        text = rviz_config(f.read(), view)
    path = os.path.join(out_dir, RVIZ_CONFIG)
    with open(path, 'w') as f:
        f.write(text)
    return path, view, cfg


def rviz_argv(config: str) -> List[str]:
    return ['rviz', '-d', config]


def open_rviz(start: Callable[[], Any], display: str, view: ViewConfig) -> Optional[Any]:
    """``start()`` rviz (returns its process: anything with ``poll()``) and wait until its window shows; started
    again when it ends first (Mesa's software GL sometimes crashes rviz as it starts), ``view.rviz_attempts`` times
    in all. The process, or None when no attempt showed a window."""
    from cnr_harness import WaitTimeout, wait_until
    from cnr_viz.screenshot import window_present
    for _ in range(view.rviz_attempts):
        proc = start()
        try:
            wait_until(lambda: proc.poll() is not None or window_present(display, view.window_title),
                       view.window_timeout, "rviz's window", interval=0.2)
        except WaitTimeout:
            return proc               # still starting: the screenshot waits for it again
        if proc.poll() is None:
            return proc
    return None


def record_topics(config_dir: str) -> List[str]:
    sec = Section.from_file(os.path.join(config_dir, 'viz.yaml')).section('viz').section('record')
    topics = sec.raw('topics')
    if not isinstance(topics, list) or not topics or not all(isinstance(t, str) and t.startswith('/') for t in topics):
        raise sec.error('topics', f'expected a list of topic names, got {topics!r}')
    return topics


def record_argv(config_dir: str, report_dir: str) -> List[str]:
    """``rosbag record`` of the mission's topics into ``report_dir/mission.bag`` (SIGINT closes the bag)."""
    return ['rosbag', 'record', '--quiet', '-O', os.path.join(report_dir, BAG), *record_topics(config_dir)]


def screenshot(display: str, view: ViewConfig, report_dir: str) -> str:
    """rviz's window (waited for up to ``view.window_timeout``) as ``report_dir/view.png`` and where its render
    panel is in it (x, y, width, height px, ``logs/rviz_panel.json``: where a map point lands, with
    :meth:`TopDownView.project`); the image's path."""
    from cnr_harness import wait_until
    from cnr_viz.screenshot import grab, render_panel, window_present
    title = view.window_title
    wait_until(lambda: window_present(display, title), view.window_timeout, "rviz's window")
    path = os.path.join(report_dir, SCREENSHOT)
    panel = render_panel(display, title)
    grab(display, title, path)
    if panel is not None:
        os.makedirs(os.path.join(report_dir, 'logs'), exist_ok=True)
        with open(os.path.join(report_dir, 'logs', PANEL), 'w') as f:
            json.dump(list(panel), f)
    return path
