"""The mission's view as markers, built from plain data (ROS-free).

:class:`VizConfig` is ``config/viz.yaml`` (no defaults in code); :class:`Scene` is what the node has heard (the
mapcell grid and temperatures, the search, the goals, the hotspot, the robot's pose, where each module runs, the
link's profile); :func:`build` turns a scene into :class:`MarkerSpec` s, which the node converts one to one into
``visualization_msgs/Marker`` (same field names: ``ns``, ``id``, ``type``, ``scale``, ``color``, ``points``,
``colors``, ``text``). Colours: mapcells blue below the ambient, white at it, red at the detection threshold
(ambient + delta, mfg's) and above; the colour bar beside the grid marks both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

from cnr_maps.grid import MapcellGrid
from cnr_params import Section

RGBA = Tuple[float, float, float, float]
Point = Tuple[float, float, float]
COLOR_NAMES = ('unvisited', 'cool', 'ambient', 'hot', 'hotspot', 'investigation', 'checked', 'global_goal',
               'mfg_goal', 'link_up', 'dead_zone', 'robot', 'text')
TOPIC_NAMES = ('cell_states', 'measurements', 'search_state', 'hotspot', 'global_goal', 'pose', 'placement')


@dataclass(frozen=True)
class Layout:
    legend_gap: float
    legend_height: float
    text_gap: float
    text_size: float
    line_spacing: float
    cell_labels: bool
    outline_width: float


@dataclass(frozen=True)
class VizConfig:
    frame_id: str
    rate: float                        # Hz (wall)
    topics: Dict[str, str]
    modules: Tuple[str, ...]
    below_ambient: float               # degC
    above_threshold: float             # degC
    steps: int
    layout: Layout
    robot_radius: float                # m
    colors: Dict[str, RGBA]

    @classmethod
    def from_section(cls, p: Section) -> 'VizConfig':
        """``viz: {...}`` of config/viz.yaml; a missing or bad field is a ConfigError naming it."""
        v = p.section('viz')
        t = v.section('topics')
        s = v.section('scale')
        lay = v.section('layout')
        c = v.section('colors')
        colors = {}
        for name in COLOR_NAMES:
            rgba = c.vector(name, 4)
            if not all(0.0 <= x <= 1.0 for x in rgba):
                raise c.error(name, f'expected r, g, b, a in 0..1, got {rgba}')
            colors[name] = tuple(rgba)
        modules = v.raw('modules')
        if not isinstance(modules, list) or not all(isinstance(m, str) and m for m in modules):
            raise v.error('modules', f'expected a list of module names, got {modules!r}')
        return cls(frame_id=v.string('frame_id'), rate=v.number('rate', positive=True),
                   topics={k: t.string(k) for k in TOPIC_NAMES}, modules=tuple(modules),
                   below_ambient=s.number('below_ambient', positive=True),
                   above_threshold=s.number('above_threshold', positive=True),
                   steps=s.integer('steps', minimum=2),
                   layout=Layout(legend_gap=lay.number('legend_gap', nonnegative=True),
                                 legend_height=lay.number('legend_height', positive=True),
                                 text_gap=lay.number('text_gap', nonnegative=True),
                                 text_size=lay.number('text_size', positive=True),
                                 line_spacing=lay.number('line_spacing', positive=True),
                                 cell_labels=lay.boolean('cell_labels'),
                                 outline_width=lay.number('outline_width', positive=True)),
                   robot_radius=v.number('robot_radius', positive=True), colors=colors)


@dataclass(frozen=True)
class ColorScale:
    """Temperature → colour: ``cool`` at ``ambient - below``, ``ambient`` at the ambient, ``hot`` at the threshold
    and above (linear in between)."""

    ambient: float
    threshold: float
    low: float
    high: float
    cool: RGBA
    mid: RGBA
    hot: RGBA

    @classmethod
    def of(cls, cfg: VizConfig, ambient: float, threshold: float) -> 'ColorScale':
        return cls(ambient, threshold, ambient - cfg.below_ambient, threshold + cfg.above_threshold,
                   cfg.colors['cool'], cfg.colors['ambient'], cfg.colors['hot'])

    def color(self, t: float) -> RGBA:
        if t <= self.ambient:
            f = 0.0 if self.ambient <= self.low else min(1.0, max(0.0, (t - self.low) / (self.ambient - self.low)))
            a, b = self.cool, self.mid
        else:
            f = min(1.0, (t - self.ambient) / (self.threshold - self.ambient)) if self.threshold > self.ambient else 1.0
            a, b = self.mid, self.hot
        return tuple(x * (1.0 - f) + y * f for x, y in zip(a, b))


@dataclass(frozen=True)
class Zone:
    """A rectangle of the link map with its conditions: ``dead`` when the link is out there."""

    name: str
    x_min: float
    x_max: float
    y_min: float
    y_max: float
    dead: bool


def link_zones(regions: Sequence[Tuple[str, float, float, float, float, bool]], default_dead: bool,
               bounds: Tuple[float, float, float, float]) -> List[Zone]:
    """The link map over ``bounds`` (x_min, y_min, x_max, y_max) as rectangles: every region (name, x_min, x_max,
    y_min, y_max, outage) clipped to the bounds, and the rest (the map's default conditions, e.g. the dead zone
    between the corridor's ends) split along the regions' edges; the first region containing a point wins, as
    in the link map."""
    bx0, by0, bx1, by1 = bounds
    xs = sorted({bx0, bx1, *(min(max(v, bx0), bx1) for r in regions for v in (r[1], r[2]))})
    ys = sorted({by0, by1, *(min(max(v, by0), by1) for r in regions for v in (r[3], r[4]))})
    strips: List[Zone] = []
    for y0, y1 in zip(ys, ys[1:]):
        row: List[Zone] = []
        for x0, x1 in zip(xs, xs[1:]):
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            hit = next((r for r in regions if r[1] <= cx <= r[2] and r[3] <= cy <= r[4]), None)
            name, dead = (hit[0], hit[5]) if hit else ('default', default_dead)
            if row and row[-1].name == name and row[-1].x_max == x0:
                row[-1] = Zone(name, row[-1].x_min, x1, y0, y1, dead)
            else:
                row.append(Zone(name, x0, x1, y0, y1, dead))
        for z in row:                  # merge with the strip below when it is the same rectangle
            below = next((i for i, b in enumerate(strips) if b.name == z.name and b.x_min == z.x_min
                          and b.x_max == z.x_max and b.y_max == z.y_min), None)
            if below is None:
                strips.append(z)
            else:
                b = strips[below]
                strips[below] = Zone(b.name, b.x_min, b.x_max, b.y_min, z.y_max, b.dead)
    return strips


@dataclass
class Scene:
    """What the view shows; every field may be missing (None / empty) until its topic has been heard."""

    grid: Optional[MapcellGrid] = None
    means: Dict[int, float] = field(default_factory=dict)          # cell -> mean temperature (local_mapcell_manager)
    latest: Dict[int, float] = field(default_factory=dict)         # cell -> latest measured temperature
    mode: str = ''                                                 # mfg's PATROL / SEARCH / DONE / IDLE
    mfg_goal: int = -1                                             # the cell mfg drives to
    investigation: int = -1
    checked: Tuple[int, ...] = ()
    hotspot: Optional[Tuple[int, float]] = None                    # cell, temperature
    global_goal: Optional[Tuple[float, float]] = None
    robot: Optional[Tuple[float, float, float]] = None             # x, y, yaw
    hosts: Dict[str, Tuple[str, int]] = field(default_factory=dict)  # module -> (host, term); '' host = none
    placement_source: str = ''                                     # e.g. 'one master', 'migration_manager'
    link: Optional[Tuple[bool, float, float]] = None               # alive, RTT [s], R_bw
    zones: Tuple[Zone, ...] = ()

    def cell_temperature(self, cell: int) -> float:
        """The latest measurement in the cell, else the cell's mean, else NaN (never measured)."""
        t = self.latest.get(cell)
        return t if t is not None else self.means.get(cell, math.nan)


@dataclass
class MarkerSpec:
    """One visualization_msgs/Marker, ROS-free (``type`` is the Marker constant's name)."""

    ns: str
    id: int
    type: str
    position: Point = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    scale: Point = (1.0, 1.0, 1.0)
    color: RGBA = (1.0, 1.0, 1.0, 1.0)
    points: List[Point] = field(default_factory=list)
    colors: List[RGBA] = field(default_factory=list)
    text: str = ''

    @property
    def key(self) -> Tuple[str, int]:
        return self.ns, self.id


def _outline(x0: float, y0: float, x1: float, y1: float, z: float) -> List[Point]:
    """The four edges of a rectangle as LINE_LIST point pairs."""
    c = [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]
    return [p for i in range(4) for p in (c[i], c[(i + 1) % 4])]


def _fmt_rtt(rtt: float) -> str:
    return f'{1000.0 * rtt:.1f} ms' if math.isfinite(rtt) else '? ms'


def module_line(module: str, host: str, term: int, link: Optional[Tuple[bool, float, float]]) -> str:
    """One module's line: where it runs, its term, and the link's RTT and R_bw (when a link is profiled)."""
    where = host or 'nowhere (migrating)'
    line = f'{module}: {where}' + (f' (term {term})' if term else '')
    if link is not None:
        alive, rtt, r_bw = link
        r = f'{r_bw:.3g}' if math.isfinite(r_bw) else '?'
        line += f'  RTT {_fmt_rtt(rtt)}  R_bw {r}' if alive else '  link DOWN'
    return line


def build(scene: Scene, cfg: VizConfig, scale: ColorScale) -> List[MarkerSpec]:
    """Every marker of the view for ``scene`` (the same (ns, id) for the same thing across calls)."""
    out: List[MarkerSpec] = []
    col = cfg.colors
    lay = cfg.layout
    for i, z in enumerate(scene.zones):      # the link map's regions under everything
        out.append(MarkerSpec('link_map', i, 'CUBE', ((z.x_min + z.x_max) / 2, (z.y_min + z.y_max) / 2, -0.02),
                              scale=(z.x_max - z.x_min, z.y_max - z.y_min, 0.01),
                              color=col['dead_zone'] if z.dead else col['link_up']))
        out.append(MarkerSpec('link_map_text', i, 'TEXT_VIEW_FACING',
                              ((z.x_min + z.x_max) / 2, z.y_min + 0.15, 0.3), scale=(0, 0, lay.text_size * 0.8),
                              color=col['text'], text=('dead zone' if z.dead else f'link: {z.name}')))
    g = scene.grid
    if g is not None:
        pts, cols = [], []
        for c in g.cells():
            pts.append((c.center_x, c.center_y, 0.0))
            t = scene.cell_temperature(c.index)
            cols.append(scale.color(t) if math.isfinite(t) else col['unvisited'])
        s = g.cell_size * 0.96
        out.append(MarkerSpec('mapcells', 0, 'CUBE_LIST', scale=(s, s, 0.02), color=(1, 1, 1, 1), points=pts,
                              colors=cols))
        if lay.cell_labels:
            for c in g.cells():
                t = scene.cell_temperature(c.index)
                if math.isfinite(t):
                    out.append(MarkerSpec('cell_temperature', c.index, 'TEXT_VIEW_FACING',
                                          (c.center_x, c.center_y, 0.2), scale=(0, 0, lay.text_size * 0.8),
                                          color=(0.0, 0.0, 0.0, 1.0), text=f'{t:.1f}'))
        out.extend(_legend(g, cfg, scale))
        w = lay.outline_width
        checked = [p for cell in scene.checked if 0 <= cell < len(g)
                   for p in _outline(*_inset(g, cell, w), 0.05)]
        if checked:
            out.append(MarkerSpec('search', 0, 'LINE_LIST', scale=(w, 0, 0), color=col['checked'], points=checked))
        if 0 <= scene.investigation < len(g):
            out.append(MarkerSpec('search', 1, 'LINE_LIST', scale=(w, 0, 0), color=col['investigation'],
                                  points=_outline(*_inset(g, scene.investigation, 2 * w), 0.06)))
        if 0 <= scene.mfg_goal < len(g):
            c = g.cell(scene.mfg_goal)
            out.append(MarkerSpec('goals', 1, 'SPHERE', (c.center_x, c.center_y, 0.15), scale=(0.25, 0.25, 0.25),
                                  color=col['mfg_goal']))
        if scene.hotspot is not None and 0 <= scene.hotspot[0] < len(g):
            cell, temp = scene.hotspot
            c = g.cell(cell)
            out.append(MarkerSpec('hotspot', 0, 'LINE_LIST', scale=(2 * w, 0, 0), color=col['hotspot'],
                                  points=_outline(*_inset(g, cell, w), 0.1)))
            out.append(MarkerSpec('hotspot', 1, 'CYLINDER', (c.center_x, c.center_y, 0.1),
                                  scale=(0.35 * g.cell_size, 0.35 * g.cell_size, 0.05), color=col['hotspot']))
            out.append(MarkerSpec('hotspot', 2, 'TEXT_VIEW_FACING', (c.center_x, g.min_y - 0.35, 0.3),
                                  scale=(0, 0, lay.text_size), color=col['hotspot'],
                                  text=f'HOTSPOT cell {cell}: {temp:.1f} degC'))
        # text is centred on its position: the lines stand centred above the grid, the heading on top
        lines = [module_line(m, *scene.hosts.get(m, ('?', 0)), scene.link) for m in cfg.modules]
        head = f'where the modules run ({scene.placement_source})' if scene.placement_source else 'modules'
        if scene.mode:
            head += f'; mfg {scene.mode}'
        texts = [head] + lines
        for i, text in enumerate(texts):
            out.append(MarkerSpec('placement', i, 'TEXT_VIEW_FACING',
                                  ((g.min_x + g.max_x) / 2,
                                   g.max_y + lay.text_gap + (len(texts) - 1 - i) * lay.line_spacing, 0.3),
                                  scale=(0, 0, lay.text_size), color=col['text'], text=text))
    if scene.global_goal is not None:
        x, y = scene.global_goal
        out.append(MarkerSpec('goals', 0, 'CYLINDER', (x, y, 0.15), scale=(0.3, 0.3, 0.3), color=col['global_goal']))
    if scene.robot is not None:
        x, y, yaw = scene.robot
        r = cfg.robot_radius
        out.append(MarkerSpec('robot', 0, 'CYLINDER', (x, y, 0.2), yaw=yaw, scale=(2 * r, 2 * r, 0.12),
                              color=col['robot']))
        out.append(MarkerSpec('robot', 1, 'ARROW', (x, y, 0.3), yaw=yaw, scale=(1.6 * r, 0.08, 0.08),
                              color=col['text']))
    return out


def _inset(g: MapcellGrid, cell: int, by: float) -> Tuple[float, float, float, float]:
    c = g.cell(cell)
    return c.min_x + by, c.min_y + by, c.max_x - by, c.max_y - by


def _legend(g: MapcellGrid, cfg: VizConfig, scale: ColorScale) -> List[MarkerSpec]:
    """The colour bar under the grid, from ``scale.low`` to ``scale.high``, with the ambient and the threshold
    marked by a tick and a label."""
    lay = cfg.layout
    n = cfg.steps
    width = g.max_x - g.min_x
    y = g.min_y - lay.legend_gap - lay.legend_height / 2
    step = width / n
    span = scale.high - scale.low

    def x_of(t: float) -> float:
        return g.min_x + (t - scale.low) / span * width

    pts = [(g.min_x + (i + 0.5) * step, y, 0.0) for i in range(n)]
    cols = [scale.color(scale.low + (i + 0.5) * span / n) for i in range(n)]
    out = [MarkerSpec('scale', 0, 'CUBE_LIST', scale=(step, lay.legend_height, 0.02), color=(1, 1, 1, 1),
                      points=pts, colors=cols)]
    ticks = []
    for i, (t, label) in enumerate(((scale.ambient, 'ambient'), (scale.threshold, 'threshold'))):
        x = x_of(t)
        ticks += [(x, y - lay.legend_height, 0.05), (x, y + lay.legend_height, 0.05)]
        out.append(MarkerSpec('scale', 2 + i, 'TEXT_VIEW_FACING', (x, y - lay.legend_height - 0.2, 0.3),
                              scale=(0, 0, lay.text_size * 0.8), color=cfg.colors['text'],
                              text=f'{label} {t:.1f} degC'))
    out.append(MarkerSpec('scale', 1, 'LINE_LIST', scale=(0.05, 0, 0), color=cfg.colors['text'], points=ticks))
    for i, t in enumerate((scale.low, scale.high)):
        out.append(MarkerSpec('scale', 4 + i, 'TEXT_VIEW_FACING', (x_of(t), y + lay.legend_height, 0.3),
                              scale=(0, 0, lay.text_size * 0.7), color=cfg.colors['text'], text=f'{t:.0f}'))
    return out


def stale_keys(previous: Sequence[Tuple[str, int]], current: Sequence[MarkerSpec]) -> List[Tuple[str, int]]:
    """Markers published before and not now: the node deletes them (a goal reached, a search over)."""
    now = {m.key for m in current}
    return [k for k in previous if k not in now]
