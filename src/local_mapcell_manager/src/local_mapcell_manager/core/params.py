"""local_mapcell_manager's parameters, read from a :class:`cnr_params.Section` (ROS-free, no defaults in code).

The defaults live in ``config/local_mapcell_manager.yaml``; the grid comes from the scenario's ``mapcells``;
``store`` and ``map_file`` are set by mission.launch.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Optional

from cnr_maps.grid import MapcellGrid
from cnr_maps.mapio import OccupancyMap, load_map
from cnr_params import Section
from cnr_store_forward.core.config import Common, common_from_section


@dataclass
class RelayParams:
    """The store-and-forward stream whose receiving end the node is (README "Input through the relay")."""
    common: Common               # stream, topic_prefix: <topic_prefix>/<stream>/data and .../ack
    ack_period: float            # s, the ack repeated this often while active
    fsync: bool                  # fsync the delivered mark after each batch


@dataclass
class ManagerParams:
    grid: MapcellGrid
    store: str
    reset_store: bool
    map_file: str
    publish_period: float
    frame_id: str
    standby_buffer: int          # readings a migration standby keeps (README "Migration state")
    recover_service: str         # the merger's GetRecentMeasurements ('' = no recovery; README "Recovery")
    recover_timeout: float       # s
    relay: Optional[RelayParams]     # None: merged_measurements subscribed directly


def read_grid(p: Section, occupancy: OccupancyMap) -> MapcellGrid:
    """The scenario's ``mapcells`` grid, checked to lie inside the map (the scenario check uses it too)."""
    grid = MapcellGrid.from_section(p.section('mapcells'))
    grid.check_inside(occupancy.bounds(), p.source, p.path('mapcells'))
    return grid


def read_relay(p: Section) -> Optional[RelayParams]:
    """``~relay_stream`` ('' = none) and the relay's settings in ``~relay`` (config/store_forward.yaml)."""
    stream = p.string('relay_stream')
    if not stream:
        return None
    r = p.section('relay')
    common = common_from_section(Section({**r.data, 'stream': stream}, r.source, r.prefix))
    receiver = r.section('receiver')
    return RelayParams(common=common, ack_period=receiver.number('ack_period', positive=True),
                       fsync=receiver.boolean('fsync'))


def read_params(p: Section) -> ManagerParams:
    map_file = p.file_path('map_file')
    return ManagerParams(grid=read_grid(p, load_map(map_file)), store=os.path.expanduser(p.string('store')),
                         reset_store=p.boolean('reset_store'), map_file=map_file,
                         publish_period=1.0 / p.number('max_publish_rate', positive=True),
                         frame_id=p.string('frame_id'), standby_buffer=p.integer('standby_buffer', minimum=1),
                         recover_service=p.string('recover_service'),
                         recover_timeout=p.number('recover_timeout', positive=True), relay=read_relay(p))
