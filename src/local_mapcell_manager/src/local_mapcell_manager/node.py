"""``local_mapcell_manager``: mapcells with visits, measurements and statistics; services and a disk store."""
from __future__ import annotations

import math
import os
import threading

import rospy

import cnr_params
from cnr_msgs.msg import CellState as CellStateMsg
from cnr_msgs.msg import CellStates, MergedMeasurement
from cnr_msgs.srv import (GetCell, GetCellResponse, GetCellStates, GetCellStatesResponse, GetMeasurements,
                          GetMeasurementsResponse)
from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import Measurement
from cnr_params.ros import init_node, private_section, quiet_at_shutdown
from local_mapcell_manager.core.params import ManagerParams, read_params
from local_mapcell_manager.core.store import CellBook, MeasurementStore


def cell_msg(grid: MapcellGrid, book: CellBook, index: int) -> CellStateMsg:
    c, s = grid.cell(index), book.states[index]
    return CellStateMsg(index=c.index, row=c.row, col=c.col, min_x=c.min_x, max_x=c.max_x, min_y=c.min_y,
                        max_y=c.max_y, center_x=c.center_x, center_y=c.center_y,
                        last_visit=rospy.Time.from_sec(s.last_visit), visit_count=s.visit_count,
                        measurement_count=s.n, mean_temperature=s.mean, std_temperature=s.std,
                        min_temperature=s.min, max_temperature=s.max)


def _key(time: float, x: float, y: float, temperature: float) -> tuple:
    """A measurement's identity at the store's precision (cnr_maps.measurements: 6 decimals of s, 4 of m, degC)."""
    return round(time, 6), round(x, 4), round(y, 4), round(temperature, 4)


class ManagerNode:
    def __init__(self, p: ManagerParams) -> None:
        self.p = p
        self.grid = p.grid
        self.lock = threading.Lock()
        if p.reset_store and os.path.exists(p.store):
            os.replace(p.store, p.store + '.old')
            rospy.loginfo(f'reset_store: moved the previous store to {p.store}.old')
        self.store = MeasurementStore(p.store, rospy.logwarn)
        self.book = CellBook(self.grid)
        for m in self.store.load(self.grid):
            self.book.add(m)
        rospy.loginfo(f'{len(self.grid)} mapcells ({self.grid.cols} x {self.grid.rows} of {self.grid.cell_size:g} m); '
                      f'{self.book.count} stored measurements reloaded from {p.store}')
        self.outside = 0
        # a measurement is stored once: one older than the newest stored one, or equal to it in stamp and values,
        # is a duplicate (a store-and-forward receiver that crashed between delivering and saving its mark
        # delivers again); two different readings with one stamp are both kept
        stored = self.book.measurements()
        self.newest = _key(stored[-1].time, stored[-1].x, stored[-1].y, stored[-1].temperature) if stored else None
        self.duplicates = 0
        self.pub = rospy.Publisher('cell_states', CellStates, queue_size=1, latch=True)
        self.measurement_pub = rospy.Publisher('mapcell_measurements', MergedMeasurement, queue_size=100)
        self._dirty = True
        self._last_pub = -math.inf
        rospy.Service('~get_cell', GetCell, self._get_cell)
        rospy.Service('~get_cell_states', GetCellStates, lambda _r: GetCellStatesResponse(self._states()))
        rospy.Service('~get_measurements', GetMeasurements, self._get_measurements)
        rospy.Subscriber('merged_measurements', MergedMeasurement, self._on_measurement, queue_size=100)
        rospy.Timer(rospy.Duration(p.publish_period), lambda _e: self._publish())
        self._publish(force=True)

    def _states(self) -> CellStates:
        with self.lock:
            msg = CellStates(rows=self.grid.rows, cols=self.grid.cols, cell_size=self.grid.cell_size,
                             cells=[cell_msg(self.grid, self.book, i) for i in range(len(self.grid))])
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = self.p.frame_id
        return msg

    def _publish(self, force: bool = False) -> None:
        if self._dirty or force:
            self._dirty = False
            self.pub.publish(self._states())

    @quiet_at_shutdown
    def _on_measurement(self, msg: MergedMeasurement) -> None:
        values = (msg.x, msg.y, msg.temperature, msg.header.stamp.to_sec())
        if not all(math.isfinite(v) for v in values):
            rospy.logwarn_throttle(5.0, f'ignored a merged measurement with non-finite values {values}')
            return
        with self.lock:
            key = _key(msg.header.stamp.to_sec(), msg.x, msg.y, msg.temperature)
            if self.newest is not None and (key[0] < self.newest[0] or key == self.newest):
                self.duplicates += 1
                rospy.logwarn_throttle(5.0, f'ignored {self.duplicates} measurement(s) older than or equal to the '
                                            f'newest stored one (duplicates or out of order)')
                return
            self.newest = key
            m = self.book.new_measurement(msg.header.stamp.to_sec(), msg.x, msg.y, msg.temperature,
                                          msg.pose_stamp.to_sec())
            if m is None:
                self.outside += 1
                return
            self.store.append(m)
            self.book.add(m)
        self.measurement_pub.publish(self._measurement_msg(m, msg.yaw))
        self._dirty = True

    def _measurement_msg(self, m: Measurement, yaw: float = math.nan) -> MergedMeasurement:
        """A stored measurement as a message: its cell filled, its store number in header.seq."""
        mm = MergedMeasurement(x=m.x, y=m.y, yaw=yaw, temperature=m.temperature,
                               pose_stamp=rospy.Time.from_sec(m.pose_time),
                               stamp_difference=abs(m.time - m.pose_time), cell=m.cell)
        mm.header.stamp = rospy.Time.from_sec(m.time)
        mm.header.frame_id = self.p.frame_id
        mm.header.seq = m.number
        return mm

    def _get_cell(self, req) -> GetCellResponse:
        index = self.grid.index_of(req.x, req.y)
        if index is None:
            return GetCellResponse(found=False)
        with self.lock:
            return GetCellResponse(found=True, cell=cell_msg(self.grid, self.book, index))

    def _get_measurements(self, req) -> GetMeasurementsResponse:
        if req.cell_index != -1 and not 0 <= req.cell_index < len(self.grid):
            return GetMeasurementsResponse(success=False, message=f'no cell {req.cell_index} '
                                                                   f'(0..{len(self.grid) - 1} or -1 for all)')
        with self.lock:
            ms = self.book.measurements(None if req.cell_index == -1 else req.cell_index)
        out = [self._measurement_msg(m) for m in ms]
        return GetMeasurementsResponse(success=True, message=f'{len(out)} measurements', measurements=out)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('local_mapcell_manager')
    ManagerNode(read_params(private_section('~')))
    rospy.spin()
