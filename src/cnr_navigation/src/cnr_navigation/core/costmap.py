"""Layered costmaps in the manner of costmap_2d: static layer, obstacle layer, inflation layer.

Cost values are costmap_2d's (``costmap_2d/cost_values.h``): 0 free, 253 inscribed, 254 lethal,
255 no information. Every operation is vectorised over cells and laser beams (numpy,
``scipy.ndimage.distance_transform_edt``); there are no per-cell Python loops.

Semantics kept from costmap_2d (navigation@noetic-devel):

* static layer (``static_layer.cpp``, ``interpretValue``): map value == unknown_cost_value ->
  NO_INFORMATION if ``track_unknown_space`` else FREE; value >= lethal_cost_threshold -> LETHAL;
  other values FREE when ``trinary_costmap`` else scaled to 0..254.
* obstacle layer (``obstacle_layer.cpp``): laser hits (and point-cloud points in the height band,
  :mod:`cnr_navigation.core.pointcloud`) closer than ``obstacle_range`` are marked LETHAL; cells along
  each beam up to ``raytrace_range`` are cleared (raytracing, see :meth:`ObstacleGrid.raytrace`); the
  robot footprint is cleared when ``footprint_clearing_enabled``. Marks persist until a ray clears
  them or a recovery resets the layer. The layer combines into the master grid with
  ``combination_method`` 1 (maximum, NO_INFORMATION cells skipped) or 0 (overwrite where the layer
  knows something).
* inflation layer (``inflation_layer.h``, ``computeCost``): with d the Euclidean distance from a
  cell to the nearest LETHAL cell of the master grid, cost = 254 if d = 0, 253 if
  d <= inscribed radius, else floor(252 * exp(-cost_scaling_factor * (d - inscribed radius)))
  for cells within ``ceil(inflation_radius / resolution)`` cells, 0 beyond. Distances come from one
  Euclidean distance transform instead of costmap_2d's wavefront; for a cell grid they are the
  same numbers (costmap_2d's cached distances are ``hypot`` of cell offsets).
* rolling window (``Costmap2D::updateOrigin``): the window follows the robot, snapped to whole
  cells, and keeps the obstacle marks of the overlapping part.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np
from scipy import ndimage

from cnr_navigation.core.geometry import IDENTITY, Pose2D

FREE_SPACE = 0
INSCRIBED_INFLATED_OBSTACLE = 253
LETHAL_OBSTACLE = 254
NO_INFORMATION = 255


# ---------------------------------------------------------------------------------------------
# configuration

@dataclass
class StaticLayerConfig:
    """``~<costmap>/static_layer/*`` (costmap_2d StaticLayer)."""

    enabled: bool
    track_unknown_space: bool
    lethal_cost_threshold: int
    unknown_cost_value: int
    trinary_costmap: bool
    use_maximum: bool


@dataclass
class ObstacleLayerConfig:
    """``~<costmap>/obstacle_layer/*`` (costmap_2d ObstacleLayer) for one laser source.

    Attributes:
        obstacle_range: hits farther than this from the sensor are not marked [m].
        raytrace_range: beams clear free space up to this distance [m].
        min_obstacle_height / max_obstacle_height: a planar scan marks only when the sensor's
            height lies in this band [m]; a point cloud keeps only the points in it (costmap_2d filters
            each point's z).
        inf_is_valid: out-of-range readings (inf or >= range_max) clear up to raytrace_range.
    """

    enabled: bool
    footprint_clearing_enabled: bool
    combination_method: int
    track_unknown_space: bool
    obstacle_range: float
    raytrace_range: float
    min_obstacle_height: float
    max_obstacle_height: float
    inf_is_valid: bool
    marking: bool
    clearing: bool


@dataclass
class InflationLayerConfig:
    """``~<costmap>/inflation_layer/*`` (costmap_2d InflationLayer)."""

    enabled: bool
    inflation_radius: float
    cost_scaling_factor: float
    inflate_unknown: bool


@dataclass
class CostmapConfig:
    """``~<costmap>/*`` (Costmap2DROS) with its layers.

    Attributes:
        rolling_window: the grid follows the robot (local costmap) instead of covering the map.
        width / height: size of a rolling window [m] (ignored when the static layer sizes the map).
        resolution: cell size [m] of a rolling window.
        robot_radius: radius of the circular footprint [m]; inscribed radius = robot_radius + padding.
        footprint_padding: added to the radius [m].
    """

    global_frame: str
    robot_base_frame: str
    rolling_window: bool
    width: float
    height: float
    resolution: float
    origin_x: float
    origin_y: float
    robot_radius: float
    footprint_padding: float
    update_frequency: float
    publish_frequency: float
    transform_tolerance: float
    static_layer: Optional[StaticLayerConfig]
    obstacle_layer: Optional[ObstacleLayerConfig]
    inflation_layer: Optional[InflationLayerConfig]

    @property
    def inscribed_radius(self) -> float:
        return self.robot_radius + self.footprint_padding


# ---------------------------------------------------------------------------------------------
# pure functions

def static_costs(occupancy: np.ndarray, cfg: StaticLayerConfig) -> np.ndarray:
    """Costs of an occupancy grid (int8, -1..100) as costmap_2d's StaticLayer interprets them.

    Returns:
        uint8 array of the same shape.
    """
    value = np.asarray(occupancy).astype(np.int16) & 0xFF                     # as unsigned char
    unknown = value == (cfg.unknown_cost_value & 0xFF)
    lethal = value >= cfg.lethal_cost_threshold
    if cfg.trinary_costmap:
        out = np.full(value.shape, FREE_SPACE, dtype=np.uint8)
    else:
        out = np.floor(value / float(cfg.lethal_cost_threshold) * LETHAL_OBSTACLE).clip(0, 254).astype(np.uint8)
    out[lethal] = LETHAL_OBSTACLE
    out[unknown] = NO_INFORMATION if cfg.track_unknown_space else FREE_SPACE
    return out


def inflation_cost_of_distance(distance_m: np.ndarray, resolution: float, inscribed_radius: float,
                               inflation_radius: float, cost_scaling_factor: float) -> np.ndarray:
    """move_base's inflation cost of cells at ``distance_m`` [m] from the nearest lethal cell.

    254 at distance 0, 253 up to the inscribed radius, ``floor(252 exp(-k (d - r_inscribed)))``
    out to ``ceil(inflation_radius / resolution)`` cells, 0 beyond.
    """
    d = np.asarray(distance_m, dtype=np.float64)
    cell_radius = max(0.0, math.ceil(inflation_radius / resolution - 1e-9))
    factor = np.exp(-cost_scaling_factor * (d - inscribed_radius))
    cost = np.floor((INSCRIBED_INFLATED_OBSTACLE - 1) * factor)
    cost = np.where(d <= inscribed_radius, INSCRIBED_INFLATED_OBSTACLE, cost)
    cost = np.where(d / resolution > cell_radius + 1e-9, 0, cost)
    cost = np.where(d == 0.0, LETHAL_OBSTACLE, cost)
    return cost.astype(np.uint8)


def inflate(master: np.ndarray, resolution: float, inscribed_radius: float,
            cfg: Optional[InflationLayerConfig]) -> np.ndarray:
    """Apply the inflation layer to a master grid (uint8) and return the new grid.

    Distances to the nearest LETHAL cell come from ``distance_transform_edt``, computed only in
    the bounding box of the lethal cells grown by the inflation radius (cells outside it are
    farther than the radius and get no inflation cost). NO_INFORMATION cells take the inflation
    cost only if it is >= INSCRIBED (or > 0 with ``inflate_unknown``), as costmap_2d does. No layer
    (``cfg`` None) or a disabled one inflates nothing.
    """
    lethal = master == LETHAL_OBSTACLE
    if cfg is None or not cfg.enabled or not lethal.any():
        return master.copy()
    cell_radius = int(math.ceil(cfg.inflation_radius / resolution - 1e-9))
    rows = np.flatnonzero(lethal.any(axis=1))
    cols = np.flatnonzero(lethal.any(axis=0))
    r0, r1 = max(0, rows[0] - cell_radius - 1), min(master.shape[0], rows[-1] + cell_radius + 2)
    c0, c1 = max(0, cols[0] - cell_radius - 1), min(master.shape[1], cols[-1] + cell_radius + 2)
    window = lethal[r0:r1, c0:c1]
    dist = ndimage.distance_transform_edt(~window) * resolution
    infl = inflation_cost_of_distance(dist, resolution, inscribed_radius, cfg.inflation_radius,
                                      cfg.cost_scaling_factor)
    out = master.copy()
    sub = out[r0:r1, c0:c1]
    unknown = sub == NO_INFORMATION
    threshold = 1 if cfg.inflate_unknown else INSCRIBED_INFLATED_OBSTACLE
    merged = np.maximum(sub, infl)
    merged = np.where(unknown, np.where(infl >= threshold, infl, NO_INFORMATION), merged)
    out[r0:r1, c0:c1] = merged
    return out


def occupancy_values(costs: np.ndarray) -> np.ndarray:
    """Costs (uint8) as nav_msgs/OccupancyGrid values, like costmap_2d's Costmap2DPublisher.

    0 -> 0, 253 -> 99, 254 -> 100, 255 -> -1, 1..252 -> 1 + 97 (c - 1) / 251.
    """
    table = np.empty(256, dtype=np.int8)
    table[0] = 0
    c = np.arange(1, 253)
    table[1:253] = 1 + (97 * (c - 1)) // 251
    table[253] = 99
    table[254] = 100
    table[255] = -1
    return table[costs]


def circle_footprint(radius: float, points: int = 16) -> List[Tuple[float, float]]:
    """The polygon costmap_2d makes from ``robot_radius`` (``makeFootprintFromRadius``)."""
    angles = np.arange(points) * 2.0 * math.pi / points
    return [(float(radius * math.cos(a)), float(radius * math.sin(a))) for a in angles]


# ---------------------------------------------------------------------------------------------
# grids

@dataclass
class GridGeometry:
    """Cell layout: ``width`` x ``height`` cells of ``resolution`` [m], lower-left corner at origin [m]."""

    resolution: float
    origin_x: float
    origin_y: float
    width: int
    height: int

    def world_to_cell(self, x, y) -> Tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices (not bounds-checked) of world points."""
        col = np.floor((np.asarray(x, dtype=np.float64) - self.origin_x) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(y, dtype=np.float64) - self.origin_y) / self.resolution).astype(np.int64)
        return row, col

    def inside(self, row, col) -> np.ndarray:
        return (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)

    def cell_to_world(self, row, col) -> Tuple[np.ndarray, np.ndarray]:
        """World coordinates of cell centres."""
        x = self.origin_x + (np.asarray(col) + 0.5) * self.resolution
        y = self.origin_y + (np.asarray(row) + 0.5) * self.resolution
        return x, y

    def contains(self, x: float, y: float) -> bool:
        row, col = self.world_to_cell(x, y)
        return bool(self.inside(row, col))

    @property
    def size_m(self) -> Tuple[float, float]:
        return self.width * self.resolution, self.height * self.resolution


@dataclass
class Observation:
    """One sensor message (a laser scan, or a point cloud: :mod:`cnr_navigation.core.pointcloud`) turned into
    points in the costmap frame.

    Attributes:
        sensor_x / sensor_y: sensor position [m].
        sensor_z: sensor height [m] (planar scan: every point has this height).
        mark_x / mark_y: obstacle points to mark [m].
        clear_x / clear_y: end points of the clearing rays [m].
        hit: per clearing ray, True if it ended on an obstacle (its end cell is not cleared).
    """

    sensor_x: float
    sensor_y: float
    sensor_z: float
    mark_x: np.ndarray
    mark_y: np.ndarray
    clear_x: np.ndarray
    clear_y: np.ndarray
    hit: np.ndarray


def scan_to_observation(ranges: Sequence[float], angle_min: float, angle_increment: float, range_min: float,
                        range_max: float, sensor: Pose2D, sensor_z: float, cfg: ObstacleLayerConfig) -> Observation:
    """Convert a LaserScan's ranges into marking and clearing points (vectorised over beams).

    Args:
        ranges: the scan's ranges [m] (NaN and inf allowed).
        angle_min / angle_increment: beam angles [rad] in the sensor frame.
        range_min / range_max: valid range interval of the scan [m].
        sensor: pose of the sensor frame in the costmap frame.
        sensor_z: height of the sensor above the costmap plane [m].
        cfg: ranges and flags of the obstacle layer.
    """
    r = np.asarray(ranges, dtype=np.float64)
    angles = angle_min + angle_increment * np.arange(r.size)
    finite = np.isfinite(r)
    valid = finite & (r >= range_min) & (r < range_max)
    no_hit = ~np.isnan(r) & ((r >= range_max) | np.isposinf(r))
    in_band = cfg.min_obstacle_height <= sensor_z <= cfg.max_obstacle_height
    mark = valid & (r < cfg.obstacle_range) & cfg.marking & in_band
    clear_len = np.where(valid, np.minimum(r, cfg.raytrace_range), np.nan)
    if cfg.inf_is_valid:
        clear_len = np.where(no_hit, cfg.raytrace_range, clear_len)
    clear = np.isfinite(clear_len) & cfg.clearing
    hit = valid & (r <= cfg.raytrace_range)
    cos_a, sin_a = np.cos(angles + sensor.yaw), np.sin(angles + sensor.yaw)
    return Observation(
        sensor_x=sensor.x, sensor_y=sensor.y, sensor_z=sensor_z,
        mark_x=sensor.x + r[mark] * cos_a[mark], mark_y=sensor.y + r[mark] * sin_a[mark],
        clear_x=sensor.x + clear_len[clear] * cos_a[clear], clear_y=sensor.y + clear_len[clear] * sin_a[clear],
        hit=hit[clear])


class ObstacleGrid:
    """The obstacle layer's own grid (uint8 costs) with raytrace clearing and marking."""

    def __init__(self, geometry: GridGeometry, cfg: ObstacleLayerConfig) -> None:
        self.geometry = geometry
        self.cfg = cfg
        self.default = NO_INFORMATION if cfg.track_unknown_space else FREE_SPACE
        self.grid = np.full((geometry.height, geometry.width), self.default, dtype=np.uint8)

    def reset(self) -> None:
        self.grid.fill(self.default)

    def resize(self, geometry: GridGeometry) -> None:
        self.geometry = geometry
        self.grid = np.full((geometry.height, geometry.width), self.default, dtype=np.uint8)

    def shift_to(self, origin_x: float, origin_y: float) -> None:
        """Move the window's origin to whole-cell offsets, keeping the overlapping cells."""
        g = self.geometry
        dc = int(math.floor((origin_x - g.origin_x) / g.resolution + 1e-9))
        dr = int(math.floor((origin_y - g.origin_y) / g.resolution + 1e-9))
        if dc == 0 and dr == 0:
            return
        new = np.full_like(self.grid, self.default)
        h, w = self.grid.shape
        src_r0, src_c0 = max(0, dr), max(0, dc)
        dst_r0, dst_c0 = max(0, -dr), max(0, -dc)
        nr, nc = h - abs(dr), w - abs(dc)
        if nr > 0 and nc > 0:
            new[dst_r0:dst_r0 + nr, dst_c0:dst_c0 + nc] = self.grid[src_r0:src_r0 + nr, src_c0:src_c0 + nc]
        self.grid = new
        self.geometry = GridGeometry(g.resolution, g.origin_x + dc * g.resolution, g.origin_y + dr * g.resolution,
                                     g.width, g.height)

    def raytrace(self, obs: Observation) -> None:
        """Clear the cells crossed by every clearing ray (all beams at once).

        Rays are sampled every half cell from the sensor to their end point; the end cell of a
        ray that hit something is left alone (it is marked next). Rays come ordered by direction; when
        neighbours are typically closer together than half a cell at the far end they are thinned
        first: they cross the same cells.
        """
        if obs.clear_x.size == 0:
            return
        g = self.geometry
        n = obs.clear_x.size
        dx, dy = obs.clear_x - obs.sensor_x, obs.clear_y - obs.sensor_y
        length = np.hypot(dx, dy)
        max_len = float(length.max())
        if max_len <= 0.0:
            return
        if n > 2:   # typical spacing between neighbouring rays (ordered by direction) at the far end
            spacing = max_len * float(np.median(np.abs(np.diff(np.arctan2(dy, dx)))))
            stride = max(1, int(0.5 * g.resolution / max(spacing, 1e-9)))
            if stride > 1:
                keep = np.zeros(n, dtype=bool)
                keep[::stride] = True
                keep[-1] = True
                dx, dy, length, hit = dx[keep], dy[keep], length[keep], obs.hit[keep]
            else:
                hit = obs.hit
        else:
            hit = obs.hit
        step = 0.5 * g.resolution
        t = np.arange(0.0, max_len, step)
        ux, uy = dx / np.maximum(length, 1e-12), dy / np.maximum(length, 1e-12)
        stop = np.where(hit, length - g.resolution, length)          # keep the hit cell itself
        px = obs.sensor_x + ux[:, None] * t[None, :]
        py = obs.sensor_y + uy[:, None] * t[None, :]
        valid = t[None, :] < stop[:, None]
        row, col = g.world_to_cell(px[valid], py[valid])
        inside = g.inside(row, col)
        self.grid[row[inside], col[inside]] = FREE_SPACE

    def mark(self, obs: Observation) -> None:
        if obs.mark_x.size == 0:
            return
        row, col = self.geometry.world_to_cell(obs.mark_x, obs.mark_y)
        inside = self.geometry.inside(row, col)
        self.grid[row[inside], col[inside]] = LETHAL_OBSTACLE

    def clear_disc(self, x: float, y: float, radius: float) -> None:
        """Free every cell whose centre lies within ``radius`` of (x, y) (footprint clearing)."""
        g = self.geometry
        r_cells = int(math.ceil(radius / g.resolution)) + 1
        row0, col0 = g.world_to_cell(x, y)
        rows = np.arange(int(row0) - r_cells, int(row0) + r_cells + 1)
        cols = np.arange(int(col0) - r_cells, int(col0) + r_cells + 1)
        rr, cc = np.meshgrid(rows, cols, indexing='ij')
        cx, cy = g.cell_to_world(rr, cc)
        sel = g.inside(rr, cc) & (np.hypot(cx - x, cy - y) <= radius)
        self.grid[rr[sel], cc[sel]] = FREE_SPACE

    def clear_area(self, x: float, y: float, size: float, invert: bool = False) -> None:
        """Reset cells outside (or inside, with ``invert``) the size x size square around (x, y).

        As costmap_2d's ``CostmapLayer::clearArea`` called by ClearCostmapRecovery.
        """
        g = self.geometry
        r0, c0 = g.world_to_cell(x - size / 2.0, y - size / 2.0)
        r1, c1 = g.world_to_cell(x + size / 2.0, y + size / 2.0)
        rows = np.arange(g.height)[:, None]
        cols = np.arange(g.width)[None, :]
        inside = (rows > r0) & (rows < r1) & (cols > c0) & (cols < c1)
        self.grid[inside == invert] = self.default


class LayeredCostmap:
    """A costmap_2d-like costmap: static + obstacle layers combined, then inflated.

    The global costmap covers the static map; the local costmap is a rolling window
    (``rolling_window``) around the robot. Call :meth:`set_map` when a map arrives and
    :meth:`update` with the robot pose and new observations at the update rate; read
    :attr:`costs` (uint8, row 0 at the bottom) and :attr:`geometry`.
    """

    def __init__(self, cfg: CostmapConfig, name: str = 'costmap') -> None:
        self.cfg = cfg
        self.name = name
        self.map_occupancy: Optional[np.ndarray] = None
        self.map_geometry: Optional[GridGeometry] = None
        self._static_full: Optional[np.ndarray] = None      # static costs on the map's grid
        self.geometry = self._window_geometry(0.0, 0.0)
        self.obstacles: Optional[ObstacleGrid] = None
        self._reset_obstacles()
        self.costs = np.zeros((self.geometry.height, self.geometry.width), dtype=np.uint8)
        self.static_costs = self.costs.copy()      # static layer + inflation only (no sensor data)
        self._static_master = self.costs.copy()    # static layer before inflation
        self.updated_stamp: Optional[float] = None
        self._frame_to_map = IDENTITY

    # -- configuration -------------------------------------------------------------------------
    def _window_geometry(self, cx: float, cy: float) -> GridGeometry:
        c = self.cfg
        w = max(1, int(round(c.width / c.resolution)))
        h = max(1, int(round(c.height / c.resolution)))
        if c.rolling_window:
            ox = math.floor((cx - w * c.resolution / 2.0) / c.resolution) * c.resolution
            oy = math.floor((cy - h * c.resolution / 2.0) / c.resolution) * c.resolution
        else:
            ox, oy = c.origin_x, c.origin_y
        return GridGeometry(c.resolution, ox, oy, w, h)

    def _reset_obstacles(self) -> None:
        ocfg = self.cfg.obstacle_layer
        self.obstacles = ObstacleGrid(self.geometry, ocfg) if ocfg is not None else None

    def reconfigure(self, cfg: CostmapConfig) -> None:
        """Apply new parameters; the grid is rebuilt when its size or resolution changes."""
        old = self.cfg
        self.cfg = cfg
        resize = (old.width, old.height, old.resolution, old.origin_x, old.origin_y, old.rolling_window) != \
            (cfg.width, cfg.height, cfg.resolution, cfg.origin_x, cfg.origin_y, cfg.rolling_window)
        if self.obstacles is not None and cfg.obstacle_layer is not None:
            self.obstacles.cfg = cfg.obstacle_layer
        if resize or (self.obstacles is None) != (cfg.obstacle_layer is None):
            if cfg.rolling_window or self.map_geometry is None:
                cx = self.geometry.origin_x + self.geometry.size_m[0] / 2.0
                cy = self.geometry.origin_y + self.geometry.size_m[1] / 2.0
                self.geometry = self._window_geometry(cx, cy)
            self._reset_obstacles()
        if self.map_occupancy is not None and self.map_geometry is not None:
            self.set_map(self.map_occupancy, self.map_geometry)
        else:
            self._recompute()

    # -- inputs --------------------------------------------------------------------------------
    def set_map(self, occupancy: np.ndarray, geometry: GridGeometry) -> None:
        """Take a new static map (int8 occupancy, row 0 at the bottom)."""
        self.map_occupancy = np.asarray(occupancy)
        self.map_geometry = geometry
        scfg = self.cfg.static_layer
        self._static_full = static_costs(self.map_occupancy, scfg) if scfg is not None and scfg.enabled else None
        if not self.cfg.rolling_window and scfg is not None:
            # costmap_2d's static layer resizes a non-rolling master grid to the map
            self.geometry = GridGeometry(geometry.resolution, geometry.origin_x, geometry.origin_y,
                                         geometry.width, geometry.height)
            if self.obstacles is not None:
                self.obstacles.resize(self.geometry)
        self._recompute()

    def _static_window(self, frame_to_map: Pose2D) -> Optional[np.ndarray]:
        """Static costs sampled at this grid's cell centres (nearest map cell)."""
        if self._static_full is None or self.map_geometry is None:
            return None
        g = self.geometry
        if not self.cfg.rolling_window and g == self.map_geometry:
            return self._static_full
        rows, cols = np.mgrid[0:g.height, 0:g.width]
        x, y = g.cell_to_world(rows, cols)
        mx, my = frame_to_map.apply(x, y)
        mr, mc = self.map_geometry.world_to_cell(mx, my)
        inside = self.map_geometry.inside(mr, mc)
        scfg = self.cfg.static_layer
        outside_value = NO_INFORMATION if scfg is not None and scfg.track_unknown_space else FREE_SPACE
        out = np.full(mr.shape, outside_value, dtype=np.uint8)
        out[inside] = self._static_full[mr[inside], mc[inside]]
        return out

    def update(self, robot: Pose2D, observations: Sequence[Observation] = (), frame_to_map: Pose2D = IDENTITY,
               stamp: Optional[float] = None) -> None:
        """One costmap update cycle: move the window, raytrace and mark, combine, inflate.

        Args:
            robot: robot pose in this costmap's frame.
            observations: new laser observations, in this costmap's frame.
            frame_to_map: pose of this costmap's frame in the map frame (for the static layer).
            stamp: time of the update [s] (kept in :attr:`updated_stamp`).
        """
        if self.cfg.rolling_window:
            new = self._window_geometry(robot.x, robot.y)
            if self.obstacles is not None:
                self.obstacles.shift_to(new.origin_x, new.origin_y)
                self.geometry = self.obstacles.geometry
            else:
                self.geometry = new
        if self.obstacles is not None and self.cfg.obstacle_layer is not None and self.cfg.obstacle_layer.enabled:
            for obs in observations:
                self.obstacles.raytrace(obs)
            for obs in observations:
                self.obstacles.mark(obs)
            if self.cfg.obstacle_layer.footprint_clearing_enabled:
                self.obstacles.clear_disc(robot.x, robot.y, self.cfg.inscribed_radius)
        self._recompute(frame_to_map, static_changed=False)
        self.updated_stamp = stamp

    def _recompute(self, frame_to_map: Optional[Pose2D] = None, static_changed: bool = True) -> None:
        if frame_to_map is None:
            frame_to_map = self._frame_to_map
        self._frame_to_map = frame_to_map
        g = self.geometry
        inflation = self.cfg.inflation_layer
        if static_changed or self.cfg.rolling_window or self.static_costs.shape != (g.height, g.width):
            static = self._static_window(frame_to_map)
            if static is None:
                scfg = self.cfg.static_layer
                default = NO_INFORMATION if scfg is not None and scfg.track_unknown_space else FREE_SPACE
                static = np.full((g.height, g.width), default, dtype=np.uint8)
            self._static_master = static
            self.static_costs = inflate(static, g.resolution, self.cfg.inscribed_radius, inflation)
        ocfg = self.cfg.obstacle_layer
        if self.obstacles is None or ocfg is None or not ocfg.enabled:
            self.costs = self.static_costs
            return
        layer = self.obstacles.grid
        if ocfg.combination_method == 1 and self.obstacles.default != NO_INFORMATION \
                and not (self._static_master == NO_INFORMATION).any():
            # inflation of a union of lethal sets is the maximum of the separate inflations, so the
            # (cached) inflated static layer only needs the inflated obstacle marks on top
            obstacle_infl = inflate(layer, g.resolution, self.cfg.inscribed_radius, inflation)
            self.costs = np.maximum(self.static_costs, obstacle_infl)
            return
        master = self._static_master
        known = layer != NO_INFORMATION
        if ocfg.combination_method == 0:
            master = np.where(known, layer, master)
        else:
            master = np.where(known & ((master == NO_INFORMATION) | (master < layer)), layer, master)
        self.costs = inflate(master, g.resolution, self.cfg.inscribed_radius, inflation)

    def clear_obstacles(self, robot: Optional[Pose2D] = None, reset_distance: Optional[float] = None,
                        invert: bool = False) -> None:
        """Reset the obstacle layer: all of it, or outside (inside with ``invert``) a square window.

        Args:
            robot: window centre [m]; None resets the whole layer (``~clear_costmaps``).
            reset_distance: side of the square window [m].
        """
        if self.obstacles is None:
            return
        if robot is None or reset_distance is None:
            self.obstacles.reset()
        else:
            self.obstacles.clear_area(robot.x, robot.y, reset_distance, invert)
        self._recompute(static_changed=False)

    # -- queries -------------------------------------------------------------------------------
    def cost_at(self, x, y, outside: int = NO_INFORMATION) -> np.ndarray:
        """Costs at world points (vectorised); ``outside`` for points off the grid."""
        row, col = self.geometry.world_to_cell(x, y)
        inside = self.geometry.inside(row, col)
        out = np.full(np.shape(row), outside, dtype=np.uint8)
        out[inside] = self.costs[row[inside], col[inside]]
        return out
