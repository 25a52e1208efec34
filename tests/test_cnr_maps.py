"""cnr_maps without a master: the mapcell grid (lookup exact at every boundary), poses and quaternions, the
measurement TSV format, free points of a map."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from cnr_maps.grid import MapcellGrid
from cnr_maps.mapio import OccupancyMap
from cnr_maps.measurements import HEADER, Measurement, format_row, parse_row, read_tsv, write_tsv
from cnr_maps.pose import Pose2D, quaternion_to_yaw, wrap_angle, yaw_to_quaternion
from cnr_params import ConfigError, Section


def rule_index(g, x, y):
    """The thesis's rule applied to every cell as the cells report it (the reference, O(n))."""
    hits = [c.index for c in g.cells() if c.contains(x, y)]
    assert len(hits) <= 1, f'({x!r}, {y!r}) in cells {hits}'
    return hits[0] if hits else None


def probes(edges):
    """Every edge exactly, the next floats either side, mid-cells, and well outside."""
    out = []
    for e in edges:
        out += [e, math.nextafter(e, -math.inf), math.nextafter(e, math.inf), e - 1e-9, e + 1e-9]
    out += [(a + b) / 2 for a, b in zip(edges, edges[1:])]
    out += [edges[0] - 5.0, edges[-1] + 5.0]
    return out


GRIDS = [MapcellGrid(0.0, -1.0, 1.0, 11, 2),          # the corridor
         MapcellGrid(0.3, -1.1, 0.1, 7, 7),
         MapcellGrid(0.3, -1.1, 0.2, 7, 7),
         MapcellGrid(-1.1, 0.3, 0.1, 13, 5),
         MapcellGrid(0.1, 0.7, 0.3, 9, 9),
         MapcellGrid(-29.8, -34.6, 0.05, 40, 3)]


@pytest.mark.parametrize('g', GRIDS, ids=lambda g: f'{g.min_x}_{g.min_y}_{g.cell_size}')
def test_lookup_agrees_with_the_rule_at_every_boundary(g):
    xs = probes([g.edge_x(k) for k in range(g.cols + 1)])
    ys = probes([g.edge_y(k) for k in range(g.rows + 1)])
    checked = 0
    for x in xs:
        for y in ys:
            assert g.index_of(x, y) == rule_index(g, x, y), (x, y)
            checked += 1
    assert checked > 100


def test_the_old_formula_was_wrong_where_the_new_lookup_is_right():
    """ceil((x - min_x) / size) - 1 misplaces points on edges for a 0.1 m grid at 0.3 (the reason for the fix)."""
    g = MapcellGrid(0.3, -1.1, 0.1, 7, 7)
    edges = [g.edge_x(k) for k in range(g.cols + 1)]
    old = [math.ceil((e - g.min_x) / g.cell_size) - 1 for e in edges]
    exact = [g.index_of(e, g.cell(0).center_y) for e in edges]
    assert old != [None if k < 0 else k for k in range(-1, g.cols)]         # the naive estimate misses
    assert exact == [None] + list(range(g.cols))                           # edge k is max of column k - 1


def test_cells_share_edges_and_rule_cases():
    g = MapcellGrid(0.0, -1.0, 1.0, 11, 2)
    assert len(g) == 22
    for c in g.cells():
        if c.col + 1 < g.cols:
            assert c.max_x == g.cell(c.index + 1).min_x                   # the very same float
    assert g.index_of(0.0, 0.0) is None                                   # min is exclusive
    assert g.index_of(1e-9, -1.0 + 1e-9) == 0
    assert g.index_of(1.0, 0.0) == 0                                      # max is inclusive
    assert g.index_of(1.0 + 1e-9, 0.0) == 1
    assert g.index_of(11.0, 1.0) == 21
    assert g.index_of(11.01, 0.5) is None
    for bad in (math.nan, math.inf, -math.inf, 1e308, -1e308):
        assert g.index_of(bad, 0.5) is None and g.index_of(0.5, bad) is None
    assert g.cell(19).sextuplet == (8.0, 9.0, 0.0, 1.0, 8.5, 0.5)
    assert g.row_col(19) == (1, 8)
    assert sorted(g.neighbours(0, 8)) == [1, 11, 12] and sorted(g.neighbours(19, 4)) == [8, 18, 20]
    assert sorted(g.neighbours(12, 8)) == [0, 1, 2, 11, 13]
    assert g.chebyshev(0, 13) == 2
    with pytest.raises(ValueError):
        g.neighbours(0, 6)
    with pytest.raises(IndexError):
        g.cell(22)


def test_from_cell_states_reproduces_the_edges():
    g = MapcellGrid(0.3, -1.1, 0.1, 7, 5)
    msg = SimpleNamespace(rows=g.rows, cols=g.cols, cell_size=g.cell_size, cells=list(g.cells()))
    h = MapcellGrid.from_cell_states(msg)
    assert [c.sextuplet for c in h.cells()] == [c.sextuplet for c in g.cells()]


def test_grid_outside_map_and_config_errors():
    g = MapcellGrid(0.0, -1.0, 1.0, 11, 2)
    g.check_inside((-29.8, -34.6, 12.2, 3.4), 'lmm')
    with pytest.raises(ConfigError) as err:
        MapcellGrid(0.0, -1.0, 1.0, 30, 2).check_inside((-29.8, -34.6, 12.2, 3.4), 'scenario.yaml')
    assert str(err.value).startswith('scenario.yaml: mapcells: grid [0, 30]')
    with pytest.raises(ConfigError, match='mapcells.cell_size: missing'):
        MapcellGrid.from_section(Section({'min_x': 0, 'min_y': 0, 'cols': 2, 'rows': 2}, 's.yaml', 'mapcells'))
    with pytest.raises(ConfigError, match='mapcells.cols: must be >= 1'):
        MapcellGrid.from_section(Section({'min_x': 0, 'min_y': 0, 'cell_size': 1.0, 'cols': 0, 'rows': 2}, 's.yaml',
                                         'mapcells'))


# -- poses ------------------------------------------------------------------------------------------
def test_pose_quaternion_round_trip_and_compose():
    for yaw in np.linspace(-math.pi, math.pi, 17)[:-1]:
        q = yaw_to_quaternion(yaw)
        assert isinstance(q, tuple) and len(q) == 4 and math.isclose(sum(v * v for v in q), 1.0)
        assert quaternion_to_yaw(q) == pytest.approx(yaw)
    a = Pose2D(1.0, 2.0, math.pi / 2)
    b = a.compose(Pose2D(1.0, 0.0, math.pi))
    assert (b.x, b.y) == pytest.approx((1.0, 3.0)) and b.yaw == pytest.approx(-math.pi / 2)
    e = a.compose(a.inverse())
    assert (e.x, e.y, e.yaw) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    assert Pose2D() == Pose2D(0.0, 0.0, 0.0) and not Pose2D(math.nan, 0.0).is_finite()
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert np.allclose(wrap_angle(np.array([0.0, 2 * math.pi + 0.1])), [0.0, 0.1])


# -- measurement TSV --------------------------------------------------------------------------------
def test_measurement_tsv_round_trip(tmp_path):
    rows = [Measurement(1, 0.3, 0.5, 0.0, 22.1, 0, 0, 0, 0.3), Measurement(2, 0.6, 0.6, 0.0, 22.3, 11, 1, 0, 0.58)]
    path = str(tmp_path / 'm.tsv')
    write_tsv(path, rows)
    text = open(path).read().splitlines()
    assert text[0].split('\t') == HEADER and len(text) == 3
    assert read_tsv(path) == rows
    assert parse_row(format_row(rows[1]).rstrip('\n')) == rows[1]
    with pytest.raises(ValueError, match='8 fields'):
        parse_row('1\t2\t3\t4\t5\t6\t7\t8')
    with open(path, 'a') as f:
        f.write('3\tx\t0\t0\t0\t0\t0\t0\t0\n')
    with pytest.raises(ValueError, match=r'm.tsv:4:'):
        read_tsv(path)


# -- maps -------------------------------------------------------------------------------------------
def test_point_problem():
    data = np.zeros((4, 6), dtype=np.int8)
    data[1, 2], data[2, 3] = 100, -1
    m = OccupancyMap(data, 0.5, (-1.0, 0.0, 0.0), 'm.yaml')
    assert m.point_problem(-0.75, 0.25) == ''
    assert 'occupied' in m.point_problem(0.25, 0.75)              # row 1, col 2
    assert 'unknown' in m.point_problem(0.75, 1.25)               # row 2, col 3
    assert m.point_problem(5.0, 0.5) == 'outside the map'
    assert m.point_problem(math.nan, 0.5) == 'not finite'
