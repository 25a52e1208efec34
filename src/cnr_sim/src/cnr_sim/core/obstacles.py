"""Moving obstacles (people) that the laser sees and the map does not.

ROS-free. Each obstacle is a disc walking a closed or back-and-forth waypoint path at constant speed,
so its position is an exact function of time (reproducible, independent of the step size).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Sequence, Tuple

import numpy as np

from cnr_params import Section


@dataclass
class MovingObstacle:
    """A disc following waypoints.

    Attributes:
        name: for collision reports.
        waypoints: (n, 2) path [m]; n >= 2.
        speed: walking speed [m/s] (> 0).
        radius: disc radius [m] (a person: about 0.25).
        loop: True = closed loop, False = back and forth.
        start_delay: the obstacle stands at the first waypoint until this sim time [s].
    """

    name: str
    waypoints: np.ndarray
    speed: float
    radius: float
    loop: bool
    start_delay: float

    def __post_init__(self) -> None:
        pts = np.asarray(self.waypoints, dtype=float)
        if not self.loop:
            pts = np.concatenate([pts, pts[-2::-1]])
        else:
            pts = np.concatenate([pts, pts[:1]])
        self._pts = pts
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(seg)])
        self._length = float(self._cum[-1])

    def position(self, t: float) -> Tuple[float, float]:
        """Position at sim time t [m]."""
        if self._length <= 0.0:
            return float(self._pts[0, 0]), float(self._pts[0, 1])
        s = (max(t - self.start_delay, 0.0) * self.speed) % self._length
        x = float(np.interp(s, self._cum, self._pts[:, 0]))
        y = float(np.interp(s, self._cum, self._pts[:, 1]))
        return x, y


def obstacles_from_config(section: Section) -> List[MovingObstacle]:
    """Parse ``obstacles: [{name, waypoints: [[x, y], ...], speed, radius, loop, start_delay}]``."""
    out = []
    for item in section.sections('obstacles'):
        raw = item.raw('waypoints')
        if not isinstance(raw, list) or len(raw) < 2:
            raise item.error('waypoints', 'expected a list of at least two [x, y] points')
        pts = []
        for i, p in enumerate(raw):
            if (not isinstance(p, (list, tuple)) or len(p) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in p)):
                raise item.error(f'waypoints[{i}]', f'expected [x, y] finite numbers, got {p!r}')
            pts.append([float(p[0]), float(p[1])])
        out.append(MovingObstacle(name=item.string('name'), waypoints=np.array(pts),
                                  speed=item.number('speed', positive=True), radius=item.number('radius', positive=True),
                                  loop=item.boolean('loop'), start_delay=item.number('start_delay', nonnegative=True)))
    return out


def positions(obstacles: Sequence[MovingObstacle], t: float) -> Tuple[np.ndarray, np.ndarray]:
    """(k, 2) centres and (k,) radii of all obstacles at time t."""
    if not obstacles:
        return np.zeros((0, 2)), np.zeros(0)
    return (np.array([o.position(t) for o in obstacles]), np.array([o.radius for o in obstacles]))
