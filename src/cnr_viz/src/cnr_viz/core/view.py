"""The rviz view of a scenario (ROS-free): ``config/mission.rviz`` centred and scaled on the scenario's mapcell
grid, and where a point of the map lands on rviz's 3-D panel (top-down orthographic view: the view's X, Y at
the panel's centre, ``Scale`` pixels per metre, x to the right, y up)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Tuple

import yaml

from cnr_maps.grid import MapcellGrid
from cnr_params import Section


@dataclass(frozen=True)
class ViewConfig:
    panel: Tuple[float, float]         # px
    margin: Tuple[float, float]        # m
    center_shift: float                # m
    window_title: str
    window_timeout: float              # s (wall)
    rviz_attempts: int

    @classmethod
    def from_section(cls, p: Section) -> 'ViewConfig':
        v = p.section('viz').section('view')
        panel = v.vector('panel', 2)
        if min(panel) <= 0:
            raise v.error('panel', f'expected two sizes > 0 px, got {panel}')
        margin = v.vector('margin', 2)
        if min(margin) < 0:
            raise v.error('margin', f'expected two margins >= 0 m, got {margin}')
        return cls(tuple(panel), tuple(margin), v.number('center_shift'), v.string('window_title'),
                   v.number('window_timeout', positive=True), v.integer('rviz_attempts', minimum=1))


@dataclass(frozen=True)
class TopDownView:
    x: float           # m, map point at the panel's centre
    y: float
    scale: float       # px per m

    def project(self, px: float, py: float, panel: Tuple[float, float]) -> Tuple[float, float]:
        """(column, row) in the panel of the map point (px, py)."""
        return panel[0] / 2 + (px - self.x) * self.scale, panel[1] / 2 - (py - self.y) * self.scale


def fit(grid: MapcellGrid, cfg: ViewConfig) -> TopDownView:
    """The top-down view that shows the grid with its margins, as large as the panel allows."""
    w = grid.max_x - grid.min_x + 2 * cfg.margin[0]
    h = grid.max_y - grid.min_y + 2 * cfg.margin[1]
    scale = min(cfg.panel[0] / w, cfg.panel[1] / h)
    return TopDownView((grid.min_x + grid.max_x) / 2, (grid.min_y + grid.max_y) / 2 + cfg.center_shift, scale)


def rviz_config(template: str, view: TopDownView) -> str:
    """``template`` (an rviz config's text) with its current view set to ``view``."""
    doc = yaml.safe_load(template)
    current = doc['Visualization Manager']['Views']['Current']
    if current.get('Class') != 'rviz/TopDownOrtho':
        raise ValueError(f"the rviz config's current view is {current.get('Class')}, not rviz/TopDownOrtho")
    current.update({'X': round(view.x, 3), 'Y': round(view.y, 3), 'Scale': round(view.scale, 3)})
    return yaml.safe_dump(doc, sort_keys=False)
