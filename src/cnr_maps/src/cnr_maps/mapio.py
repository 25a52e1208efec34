"""map_server-compatible map loading (YAML + image), with map_server's exact semantics.

Follows ``navigation@noetic-devel:map_server/src/{main,image_loader}.cpp``:

* YAML keys ``image`` (relative to the YAML file), ``resolution`` [m/pixel],
  ``origin`` [x, y, yaw] (pose of the lower-left pixel), ``negate``,
  ``occupied_thresh``, ``free_thresh``, optional ``mode`` (trinary | scale | raw).
* Per pixel: average the channels (alpha included in trinary mode or when there is no
  alpha channel), negate if asked, then raw stores the average; otherwise
  p = (255 - avg) / 255, p > occ → 100, p < free → 0, else trinary → -1 and scale →
  -1 if alpha is 0 else 1 + 98 (p - free) / (occ - free).
* Image row 0 becomes the last grid row (grid row 0 is the bottom, ``origin``'s row).

Every problem raises :class:`cnr_params.ConfigError` naming the file and field.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Tuple

import numpy as np

from cnr_params import ConfigError, Section, load_yaml

MODES = ('trinary', 'scale', 'raw')
OCCUPIED, FREE, UNKNOWN = 100, 0, -1


@dataclass
class OccupancyMap:
    """An occupancy grid in ROS conventions.

    Attributes:
        data: int8 array (rows = height, cols = width); row 0 is the bottom (y = origin y).
        resolution: metres per cell.
        origin: (x, y, yaw) of the lower-left corner of cell (0, 0) in the map frame.
        source: the file the map came from (for messages).
    """

    data: np.ndarray
    resolution: float
    origin: Tuple[float, float, float]
    source: str = ''

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    def world_to_cell(self, x, y):
        """Cell indices (row, col) of world points (arrays allowed; yaw of origin ignored as map_server's users do)."""
        col = np.floor((np.asarray(x) - self.origin[0]) / self.resolution).astype(int)
        row = np.floor((np.asarray(y) - self.origin[1]) / self.resolution).astype(int)
        return row, col

    def cell_to_world(self, row, col):
        """World coordinates of cell centres."""
        x = self.origin[0] + (np.asarray(col) + 0.5) * self.resolution
        y = self.origin[1] + (np.asarray(row) + 0.5) * self.resolution
        return x, y

    def contains(self, x: float, y: float) -> bool:
        row, col = self.world_to_cell(x, y)
        return bool(0 <= row < self.height and 0 <= col < self.width)

    def point_problem(self, x: float, y: float) -> str:
        """Why (x, y) is not a free point of the map ('' if it is): not finite, outside, occupied or unknown cell."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return 'not finite'
        if not self.contains(x, y):
            return 'outside the map'
        row, col = self.world_to_cell(x, y)
        value = int(self.data[row, col])
        if value == UNKNOWN:
            return 'on an unknown map cell'
        if value != FREE:
            return f'on an occupied map cell (value {value})'
        return ''

    def bounds(self) -> Tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the map in metres."""
        x0, y0 = self.origin[0], self.origin[1]
        return x0, y0, x0 + self.width * self.resolution, y0 + self.height * self.resolution


def pixels_to_occupancy(pixels: np.ndarray, *, negate: bool, occupied_thresh: float, free_thresh: float,
                        mode: str = 'trinary') -> np.ndarray:
    """Convert an image array (H x W or H x W x C, uint8, row 0 at the top) to an int8 grid (row 0 at the bottom).

    Vectorised version of map_server's ``loadMapFromFile`` loop.
    """
    img = np.asarray(pixels)
    if img.ndim == 2:
        img = img[:, :, None]
    channels = img.shape[2]
    has_alpha = channels in (2, 4)
    color = img.astype(np.float64)
    if mode == 'trinary' or not has_alpha:
        avg = color.sum(axis=2) / channels
    else:
        avg = color[:, :, :channels - 1].sum(axis=2) / (channels - 1)
    if negate:
        avg = 255.0 - avg
    if mode == 'raw':
        grid = avg.astype(np.int64).astype(np.int8)          # map_server: (int8) value
    else:
        occ = (255.0 - avg) / 255.0
        grid = np.full(avg.shape, UNKNOWN, dtype=np.int8)
        if mode == 'scale':
            alpha = img[:, :, channels - 1] if has_alpha else np.full(avg.shape, 255)
            scaled = 1 + 98 * (occ - free_thresh) / (occupied_thresh - free_thresh)
            grid = np.where(alpha == 0, UNKNOWN, scaled.astype(np.int64)).astype(np.int8)
        grid[occ > occupied_thresh] = OCCUPIED
        grid[occ < free_thresh] = FREE
    return np.ascontiguousarray(grid[::-1])


def _read_image(path: str, yaml_path: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError
    if not os.path.isfile(path):
        raise ConfigError(yaml_path, 'image', f'file not found: {path}')
    try:
        with Image.open(path) as im:
            im.load()
            if im.mode in ('P', 'I;16', 'I', 'F', '1'):
                im = im.convert('RGBA' if 'transparency' in im.info else 'L')
            return np.asarray(im, dtype=np.uint8)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise ConfigError(yaml_path, 'image', f'cannot read {os.path.basename(path)}: {exc}') from None


def load_map(yaml_path: str) -> OccupancyMap:
    """Load a map_server YAML file and its image.

    Raises:
        ConfigError: naming the YAML file and the field (or the image) at fault.
    """
    sec = Section(load_yaml(yaml_path), yaml_path)
    for key in ('image', 'resolution', 'origin', 'negate', 'occupied_thresh', 'free_thresh'):
        if key not in sec:
            raise sec.error(key, 'missing (map_server requires it)')
    resolution = sec.number('resolution', positive=True)
    origin = sec.vector('origin', 3)
    negate = sec.raw('negate')
    if isinstance(negate, bool):
        negate = int(negate)
    if not isinstance(negate, int) or negate not in (0, 1):
        raise sec.error('negate', f'expected 0 or 1, got {negate!r}')
    occ = sec.number('occupied_thresh', minimum=0.0, maximum=1.0)
    free = sec.number('free_thresh', minimum=0.0, maximum=1.0)
    if not free < occ:
        raise sec.error('free_thresh', f'must be below occupied_thresh ({occ}), got {free}')
    mode = sec.string('mode', 'trinary', choices=MODES)       # optional in map_server's format (its default)
    image = sec.string('image')
    if not image:
        raise sec.error('image', 'empty file name')
    image_path = image if os.path.isabs(image) else os.path.join(os.path.dirname(os.path.abspath(yaml_path)), image)
    pixels = _read_image(image_path, yaml_path)
    data = pixels_to_occupancy(pixels, negate=bool(negate), occupied_thresh=occ, free_thresh=free, mode=mode)
    if not all(math.isfinite(v) for v in origin):
        raise sec.error('origin', 'must be finite')
    return OccupancyMap(data=data, resolution=resolution, origin=(origin[0], origin[1], origin[2]),
                        source=yaml_path)
