"""sensor_msgs/PointCloud2 data as obstacle-layer observations (ROS-free, vectorised).

costmap_2d's ObstacleLayer handles a PointCloud2 source this way (``observation_buffer.cpp`` ``bufferCloud``,
``obstacle_layer.cpp`` ``updateBounds`` / ``raytraceFreespace``), and so does :func:`cloud_to_observation`:

* the cloud is transformed into the costmap's frame with the tf at the cloud's stamp;
* points outside ``[min_obstacle_height, max_obstacle_height]`` (z in the costmap frame) are dropped, for
  marking and for clearing alike; NaN points (no depth) are dropped;
* a kept point closer than ``obstacle_range`` to the sensor origin (3-D distance) marks its cell;
* every kept point clears the cells on the 2-D line from the sensor origin to it, cut at ``raytrace_range``
  (its own cell is left for marking). Rays from the one origin whose directions differ by less than half a
  cell at ``raytrace_range`` cross the same cells, so of those only the longest is traced (all the points of
  one depth-image column share a direction).
"""
from __future__ import annotations

from typing import Mapping, Optional, Tuple

import numpy as np

from cnr_navigation.core.costmap import ObstacleLayerConfig, Observation

#: sensor_msgs/PointField datatypes -> numpy type (little endian)
POINT_FIELD_TYPES = {1: 'i1', 2: 'u1', 3: 'i2', 4: 'u2', 5: 'i4', 6: 'u4', 7: 'f4', 8: 'f8'}


def cloud_xyz(data: bytes, width: int, height: int, point_step: int, row_step: int,
              fields: Mapping[str, Tuple[int, int]], is_bigendian: bool) -> np.ndarray:
    """The x, y, z fields of a PointCloud2's data as an (N, 3) float64 array (N = width x height).

    Args:
        data: the message's ``data``.
        width / height / point_step / row_step / is_bigendian: the message's fields of those names.
        fields: field name -> (offset, PointField datatype) of at least x, y and z.

    Raises:
        ValueError: a field is missing or of an unknown type, or ``data`` is too short.
    """
    formats = []
    for name in 'xyz':
        if name not in fields:
            raise ValueError(f"no '{name}' field")
        offset, datatype = fields[name]
        if datatype not in POINT_FIELD_TYPES:
            raise ValueError(f"field '{name}' has an unknown datatype {datatype}")
        formats.append(('>' if is_bigendian else '<') + POINT_FIELD_TYPES[datatype])
    if width * point_step > row_step or len(data) < height * row_step:
        raise ValueError(f'{len(data)} bytes of data for {height} rows of {row_step} bytes '
                         f'({width} points of {point_step} bytes)')
    dtype = np.dtype({'names': ['x', 'y', 'z'], 'formats': formats,
                      'offsets': [fields[n][0] for n in 'xyz'], 'itemsize': point_step})
    raw = np.frombuffer(data, dtype=np.uint8, count=height * row_step).reshape(height, row_step)
    rows = raw[:, :width * point_step]
    if row_step != width * point_step:
        rows = np.ascontiguousarray(rows)
    points = rows.reshape(-1).view(dtype)
    out = np.empty((points.size, 3))
    out[:, 0], out[:, 1], out[:, 2] = points['x'], points['y'], points['z']
    return out


def cloud_to_observation(points: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                         cfg: ObstacleLayerConfig, resolution: float,
                         origin: Optional[np.ndarray] = None) -> Observation:
    """Turn cloud points into marking points and clearing rays in the costmap frame (see the module doc).

    Args:
        points: (N, 3) points in the cloud's frame [m] (NaN rows allowed).
        rotation / translation: (3, 3) rotation and (3,) translation of the cloud's frame in the costmap frame.
        cfg: heights, ranges and flags of the source.
        resolution: the costmap's cell size [m] (rays closer than half a cell at the far end are merged).
        origin: (3,) sensor origin in the costmap frame [m] (``sensor_frame``); None: ``translation``.
    """
    t = np.asarray(translation, dtype=np.float64)
    o = t if origin is None else np.asarray(origin, dtype=np.float64)
    p = points @ np.asarray(rotation, dtype=np.float64).T + t
    z = p[:, 2]
    with np.errstate(invalid='ignore'):
        keep = np.isfinite(p).all(axis=1) & (z >= cfg.min_obstacle_height) & (z <= cfg.max_obstacle_height)
    p = p[keep]
    dx, dy = p[:, 0] - o[0], p[:, 1] - o[1]
    flat = np.hypot(dx, dy)
    empty = np.zeros(0)
    if cfg.marking:
        mark = dx * dx + dy * dy + (p[:, 2] - o[2]) ** 2 < cfg.obstacle_range ** 2
        mark_x, mark_y = p[mark, 0], p[mark, 1]
    else:
        mark_x, mark_y = empty, empty
    clear_x, clear_y, hit = empty, empty, np.zeros(0, dtype=bool)
    if cfg.clearing and flat.size:
        # one ray per direction bin of half a cell at raytrace_range: the longest (it clears the others' cells)
        width = 0.5 * resolution / max(cfg.raytrace_range, 1e-9)
        bins = np.floor(np.arctan2(dy, dx) / width).astype(np.int64)
        order = np.lexsort((-flat, bins))
        first = np.ones(order.size, dtype=bool)
        first[1:] = bins[order[1:]] != bins[order[:-1]]
        sel = order[first]
        length = np.minimum(flat[sel], cfg.raytrace_range)
        scale = np.divide(length, flat[sel], out=np.zeros_like(length), where=flat[sel] > 0)
        clear_x, clear_y = o[0] + dx[sel] * scale, o[1] + dy[sel] * scale
        hit = flat[sel] <= cfg.raytrace_range
    return Observation(sensor_x=float(o[0]), sensor_y=float(o[1]), sensor_z=float(o[2]), mark_x=mark_x,
                       mark_y=mark_y, clear_x=clear_x, clear_y=clear_y, hit=hit)
