#!/usr/bin/env python3
"""Generate the workspace's maps in map_server format (YAML + PGM), as map_saver writes them.

    maps/generate_maps.py [--out DIR]

Writes ``corridor.{yaml,pgm}`` (the thesis's lab corridor: a 2 m x 12 m corridor whose
right 11 m carry the 11 x 2 mapcells, with the left part of the corridor mapped as well,
origin [-29.8, -34.6, 0.0] as map_saver set it in the thesis) and ``datacenter.{yaml,pgm}``
(a hall with rows of racks and aisles). Pixel values follow map_saver: free 254,
occupied 0, unknown 205; thresholds 0.65 / 0.196.

Every dimension is a constant below, in metres, so a map can be changed and regenerated.
"""
from __future__ import annotations

import argparse
import os
from typing import Tuple

import numpy as np

FREE, OCCUPIED, UNKNOWN = 254, 0, 205
RESOLUTION = 0.05

# --- the lab corridor (thesis §4.1.2, paper Appendix VI) -------------------------------------
CORRIDOR_ORIGIN = (-29.8, -34.6, 0.0)   # as map_saver wrote it in the thesis
CORRIDOR_SIZE = (42.0, 38.0)            # image extent [m]: mostly unknown, as a gmapping map
CORRIDOR_X = (-12.0, 11.5)              # free corridor floor along x [m]; mapcells cover 0..11
CORRIDOR_Y = (-1.0, 1.0)                # 2 m wide
WALL = 0.15                             # wall thickness [m]
# doorways on the mapped left part: (x_min, x_max, side) with side +1 = upper wall
DOORWAYS = [(-9.0, -8.0, +1), (-5.5, -4.5, -1)]
DOOR_DEPTH = 1.0                        # recess behind a doorway [m]

# --- the data-center hall ---------------------------------------------------------------------
HALL_ORIGIN = (-1.0, -1.0, 0.0)
HALL_SIZE = (20.0, 14.0)                # inner floor [m]
RACK_ROWS = 4                           # rows of racks along x
RACK_DEPTH = 1.0                        # [m]
RACK_LENGTH = 14.0                      # [m]
RACK_X0 = 3.0                           # first rack of each row starts here [m]
AISLE = 2.0                             # aisle between rack rows [m]
ROW_Y0 = 2.0                            # first row's lower edge [m]
RACK_GAP = (9.5, 10.5)                  # a cross aisle cuts every row here [m]


def _blank(size: Tuple[float, float], fill: int) -> np.ndarray:
    cols, rows = int(round(size[0] / RESOLUTION)), int(round(size[1] / RESOLUTION))
    return np.full((rows, cols), fill, dtype=np.uint8)   # row 0 = top of the image


def _paint(img: np.ndarray, origin, x: Tuple[float, float], y: Tuple[float, float], value: int) -> None:
    """Fill the world rectangle x × y (metres) with ``value``; the image's row 0 is the top."""
    rows = img.shape[0]
    c0, c1 = (int(round((v - origin[0]) / RESOLUTION)) for v in x)
    r0, r1 = (int(round((v - origin[1]) / RESOLUTION)) for v in y)
    if min(c0, r0) < 0 or c1 > img.shape[1] or r1 > rows:
        raise ValueError(f'rectangle x={x} y={y} lies outside the image')
    img[rows - r1:rows - r0, c0:c1] = value


def corridor() -> np.ndarray:
    img = _blank(CORRIDOR_SIZE, UNKNOWN)
    o = CORRIDOR_ORIGIN
    (x0, x1), (y0, y1) = CORRIDOR_X, CORRIDOR_Y
    _paint(img, o, (x0 - WALL, x1 + WALL), (y0 - WALL, y1 + WALL), OCCUPIED)
    for d0, d1, side in DOORWAYS:
        ys = (y1, y1 + DOOR_DEPTH) if side > 0 else (y0 - DOOR_DEPTH, y0)
        _paint(img, o, (d0 - WALL, d1 + WALL), (ys[0] - WALL, ys[1] + WALL), OCCUPIED)
    _paint(img, o, (x0, x1), (y0, y1), FREE)
    for d0, d1, side in DOORWAYS:
        ys = (y1 - WALL, y1 + DOOR_DEPTH) if side > 0 else (y0 - DOOR_DEPTH, y0 + WALL)
        _paint(img, o, (d0, d1), ys, FREE)
    return img


def datacenter() -> np.ndarray:
    img = _blank((HALL_SIZE[0] + 2.0, HALL_SIZE[1] + 2.0), UNKNOWN)
    o = HALL_ORIGIN
    _paint(img, o, (-WALL, HALL_SIZE[0] + WALL), (-WALL, HALL_SIZE[1] + WALL), OCCUPIED)
    _paint(img, o, (0.0, HALL_SIZE[0]), (0.0, HALL_SIZE[1]), FREE)
    for row in range(RACK_ROWS):
        y = ROW_Y0 + row * (RACK_DEPTH + AISLE)
        _paint(img, o, (RACK_X0, RACK_X0 + RACK_LENGTH), (y, y + RACK_DEPTH), OCCUPIED)
        _paint(img, o, RACK_GAP, (y, y + RACK_DEPTH), FREE)
    return img


def write_map(out_dir: str, name: str, img: np.ndarray, origin) -> None:
    pgm = os.path.join(out_dir, f'{name}.pgm')
    with open(pgm, 'wb') as f:
        f.write(f'P5\n# CREATOR: maps/generate_maps.py {RESOLUTION:.3f} m/pix\n'
                f'{img.shape[1]} {img.shape[0]}\n255\n'.encode('ascii'))
        f.write(img.tobytes())
    with open(os.path.join(out_dir, f'{name}.yaml'), 'w') as f:
        f.write(f'image: {name}.pgm\nresolution: {RESOLUTION:.6f}\n'
                f'origin: [{origin[0]:.6f}, {origin[1]:.6f}, {origin[2]:.6f}]\n'
                'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n')
    print(f'wrote {pgm} ({img.shape[1]} x {img.shape[0]} px)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', default=os.path.dirname(os.path.abspath(__file__)), help='output folder')
    args = parser.parse_args()
    write_map(args.out, 'corridor', corridor(), CORRIDOR_ORIGIN)
    write_map(args.out, 'datacenter', datacenter(), HALL_ORIGIN)


if __name__ == '__main__':
    main()
