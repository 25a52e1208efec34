"""mfg's parameters, read from a :class:`cnr_params.Section` (ROS-free, no defaults in code).

Everything is under ``mfg``: the defaults in ``config/mfg.yaml``, the scenario file (loaded after it) adds
or overrides the scenario-specific values (threshold, settle time, ...).
"""
from __future__ import annotations

from dataclasses import dataclass

from cnr_maps.grid import CONNECTIVITIES
from cnr_params import Section
from mfg.core.detector import DetectorConfig


@dataclass
class MfgParams:
    detector: DetectorConfig
    neighbourhood: int           # 4 (the paper's search) or 8
    settle_time: float           # s
    min_measurements: int
    measure_timeout: float       # s
    goal_timeout: float          # s
    goal_ack_timeout: float      # wall s before a goal move_base has not acknowledged is sent again
    next_goal_service: str
    next_goal_timeout: float     # wall s to wait for the global goal manager before the robot's own goal
    pose_topic: str
    suppress_radius: int         # cells
    frame_id: str
    activity_rate: float         # Hz, ~activity publication


def read_params(p: Section) -> MfgParams:
    m = p.section('mfg')
    neighbourhood = m.integer('neighbourhood')
    if neighbourhood not in CONNECTIVITIES:
        raise m.error('neighbourhood', f'must be 4 or 8, got {neighbourhood}')
    return MfgParams(detector=DetectorConfig.from_section(m.section('threshold')),
                     neighbourhood=neighbourhood,
                     settle_time=m.number('settle_time', nonnegative=True),
                     min_measurements=m.integer('min_measurements', minimum=1),
                     measure_timeout=m.number('measure_timeout', positive=True),
                     goal_timeout=m.number('goal_timeout', positive=True),
                     goal_ack_timeout=m.number('goal_ack_timeout', positive=True),
                     next_goal_service=m.string('next_goal_service'),
                     next_goal_timeout=m.number('next_goal_timeout', positive=True),
                     pose_topic=m.string('pose_topic'),
                     suppress_radius=m.integer('suppress_radius', minimum=0),
                     frame_id=m.string('frame_id'),
                     activity_rate=m.number('activity_rate', positive=True))
