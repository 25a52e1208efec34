"""The mission report: merged measurements as TSV, a JSON summary and a PNG of the mapcells (ROS-free).

Files written into the report folder:

* ``measurements.tsv`` — the stored measurements in the format of :mod:`cnr_maps.measurements`
  (written with its ``write_tsv``);
* ``summary.json`` — scenario, hotspot, sim time to find it, distance driven, battery used (the base's pack and
  the robot computer's, :class:`PackReadings`), counts;
* ``mapcells.png`` — the map with every mapcell coloured by its average temperature, the robot's path and
  the hotspot marked.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from cnr_mission.core.task import battery_used
from cnr_params.files import write_json


@dataclass
class CellSummary:
    index: int
    row: int
    col: int
    min_x: float
    max_x: float
    min_y: float
    max_y: float
    mean: float
    count: int


def path_length(points: Sequence[Tuple[float, float]]) -> float:
    """Length of a polyline [m]."""
    if len(points) < 2:
        return 0.0
    p = np.asarray(points, dtype=float)
    return float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))))


class PackReadings:
    """One battery pack's sensor_msgs/BatteryState readings over the mission: the first, the last and the first
    from the hotspot's time on."""

    def __init__(self) -> None:
        self.first = self.last = self.at_hotspot = None

    def add(self, msg, hotspot_stamp=None) -> None:
        """A reading; ``hotspot_stamp``: the hotspot's stamp once there is one (comparable with the header's)."""
        if self.first is None:
            self.first = msg
        self.last = msg
        if hotspot_stamp is not None and self.at_hotspot is None and msg.header.stamp >= hotspot_stamp:
            self.at_hotspot = msg

    def used_to_hotspot(self) -> float:
        """The fraction of the pack used from the first reading to the first from the hotspot's time on (the last
        without a hotspot); NaN without readings (:func:`cnr_mission.core.task.battery_used`)."""
        end = self.at_hotspot or self.last
        return battery_used(None if self.first is None else self.first.percentage,
                            None if end is None else end.percentage)

    def used(self) -> Optional[Dict]:
        """What the pack gave over the mission (None without a reading): ``used_percent`` [%], ``used_ah`` [Ah]
        and ``energy`` (J per consumer, the simulator's ``serial_number`` text)."""
        first, last = self.first, self.last
        if first is None:
            return None
        return dict(used_percent=100.0 * (first.percentage - last.percentage), used_ah=first.charge - last.charge,
                    energy=last.serial_number)


def write_summary(path: str, summary: Dict) -> None:
    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v
    write_json(path, clean(summary), indent=2, sort_keys=False)


def render_png(path: str, cells: Sequence[CellSummary], trajectory: Sequence[Tuple[float, float]],
               hotspot: Optional[int], title: str, occupancy: Optional[np.ndarray] = None,
               map_extent: Optional[Tuple[float, float, float, float]] = None,
               sources: Sequence[Tuple[str, float, float]] = ()) -> None:
    """Mapcells coloured by mean temperature over the map, with the path and the hotspot."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    x0 = min(c.min_x for c in cells)
    x1 = max(c.max_x for c in cells)
    y0 = min(c.min_y for c in cells)
    y1 = max(c.max_y for c in cells)
    w, h = x1 - x0, y1 - y0
    fig, ax = plt.subplots(figsize=(min(14, max(6, w * 0.9)), min(10, max(3.5, h * 0.9 + 1.5))))
    if occupancy is not None and map_extent is not None:
        shade = np.where(occupancy < 0, 0.8, np.where(occupancy >= 50, 0.15, 1.0))
        ax.imshow(shade, cmap='gray', vmin=0, vmax=1, origin='lower', extent=map_extent, interpolation='nearest')
    means = [c.mean for c in cells if math.isfinite(c.mean)]
    norm = matplotlib.colors.Normalize(vmin=min(means) if means else 0, vmax=max(means) if means else 1)
    cmap = matplotlib.cm.get_cmap('inferno')
    for c in cells:
        face = cmap(norm(c.mean)) if math.isfinite(c.mean) else (0, 0, 0, 0)
        ax.add_patch(Rectangle((c.min_x, c.min_y), c.max_x - c.min_x, c.max_y - c.min_y, facecolor=face,
                               edgecolor='steelblue', linewidth=0.6, alpha=0.75))
        if math.isfinite(c.mean) and w <= 24:
            ax.text((c.min_x + c.max_x) / 2, (c.min_y + c.max_y) / 2, f'{c.mean:.1f}', ha='center', va='center',
                    fontsize=7, color='white' if norm(c.mean) < 0.6 else 'black')
    if trajectory:
        t = np.asarray(trajectory)
        ax.plot(t[:, 0], t[:, 1], color='deepskyblue', linewidth=1.2, label='robot path')
        ax.plot(t[0, 0], t[0, 1], 'o', color='deepskyblue', markersize=6)
    for name, sx, sy in sources:
        ax.plot(sx, sy, 'x', color='red', markersize=7)
    if hotspot is not None:
        c = next(c for c in cells if c.index == hotspot)
        ax.add_patch(Rectangle((c.min_x, c.min_y), c.max_x - c.min_x, c.max_y - c.min_y, fill=False,
                               edgecolor='lime', linewidth=2.5, label=f'hotspot (cell {hotspot})'))
    sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=ax, label='cell average temperature [degC]', shrink=0.8)
    ax.set_xlim(x0 - 1.0, x1 + 1.0)
    ax.set_ylim(y0 - 1.0, y1 + 1.0)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(title)
    ax.legend(loc='upper left', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def check_store(published: Sequence[float], stored_stamps: Sequence[float]) -> Dict:
    """Every measurement published while both the store and this monitor were listening is in the store, once.
    The store keeps measurements in stamp order; the window is the stamps both saw: from the later of the two
    first ones (either subscriber may connect to a new merger first) to the earlier of the two newest ones (the
    newest may have been in flight to either when the report was written). Stamps are compared as multisets
    (two measurements may share a stamp): one published in the window more often than stored is lost
    (``missing``), one stored more often than published is a duplicate; one stored in the window that this
    monitor never saw (``unseen``) means the monitor dropped it. Outside the window: ``published_before_first``
    were made before the store was up (the two-host mission with migration_manager starts the merger only once
    the first local_mapcell_manager instance is active, so at most a connection race's worth), ``in_flight``
    after its newest."""
    stored = sorted(round(t, 6) for t in stored_stamps)
    pub = [round(t, 6) for t in published]
    shared = len(pub) - len(set(pub))
    if not stored or not pub:
        return dict(stored=len(stored), published_since_first=0, stored_in_window=0, missing_count=0, missing=[],
                    unseen=0, duplicates=len(stored) - len(set(stored)), in_flight=0,
                    published_before_first=len(pub), shared_stamps=shared)
    lo, hi = max(stored[0], min(pub)), min(stored[-1], max(pub))
    window = Counter(t for t in pub if lo <= t <= hi)
    in_store = Counter(t for t in stored if lo <= t <= hi)
    missing = sorted((window - in_store).elements())
    extra = in_store - window
    seen = set(pub)
    outside = Counter(t for t in stored if not lo <= t <= hi)
    return dict(stored=len(stored), published_since_first=sum(window.values()),
                stored_in_window=sum(in_store.values()), missing_count=len(missing), missing=missing[:50],
                unseen=sum(n for t, n in extra.items() if t not in seen),
                duplicates=sum(n for t, n in extra.items() if t in seen) + sum(n - 1 for n in outside.values()),
                in_flight=sum(1 for t in pub if t > stored[-1]),
                published_before_first=sum(1 for t in pub if t < stored[0]), shared_stamps=shared)
