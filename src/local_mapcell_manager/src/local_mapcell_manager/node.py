"""``local_mapcell_manager``: mapcells with visits, measurements and statistics; services and a disk store.

Movable by migration_manager: the node is built with the managed instance's hooks (:class:`StoreHooks`, those of
:mod:`local_mapcell_manager.migration`, which also holds the executable's ``main``). As a standby the node
buffers ``merged_measurements`` but stores, publishes and serves nothing; once active (:meth:`ManagerNode.activate`)
it stores, publishes and serves (README "Migration state"). With ``~relay_stream`` set its input is the
store-and-forward relay instead, which it acknowledges itself while active (README "Input through the relay")."""
from __future__ import annotations

import math
import os
import threading
import time
from typing import Callable, List, Optional

import rospy

from cnr_msgs.msg import CellState as CellStateMsg
from cnr_msgs.msg import CellStates, MergedMeasurement, StoreForwardAck, StoreForwardBatch
from cnr_msgs.srv import (GetCell, GetCellResponse, GetCellStates, GetCellStatesResponse, GetMeasurements,
                          GetMeasurementsResponse, GetRecentMeasurements)
from cnr_maps.grid import MapcellGrid
from cnr_maps.measurements import Measurement
from cnr_runtime import call_with_timeout, quiet_at_shutdown
from cnr_store_forward.core.receiver import Receiver
from local_mapcell_manager.core.ledger import DUPLICATE, Ledger, Reading, Replay
from local_mapcell_manager.core.params import ManagerParams
from local_mapcell_manager.core.relay import mark_path, take_batch
from local_mapcell_manager.core.store import CellBook, MeasurementStore
from migration_manager import client
from migration_manager.instance import Hooks, ManagedInstance

NOT_ACTIVE = f'{client.NOT_ACTIVE} (standby, frozen or lease lapsed)'


def cell_msg(grid: MapcellGrid, book: CellBook, index: int) -> CellStateMsg:
    c, s = grid.cell(index), book.states[index]
    return CellStateMsg(index=c.index, row=c.row, col=c.col, min_x=c.min_x, max_x=c.max_x, min_y=c.min_y,
                        max_y=c.max_y, center_x=c.center_x, center_y=c.center_y,
                        last_visit=rospy.Time.from_sec(s.last_visit), visit_count=s.visit_count,
                        measurement_count=s.n, mean_temperature=s.mean, std_temperature=s.std,
                        min_temperature=s.min, max_temperature=s.max)


class StoreHooks(Hooks):
    """The managed instance's hooks a :class:`ManagerNode` is built with."""

    def discard_prepared(self) -> None:
        """A store prepared from the replicas is not used (promoted without a state, or started)."""
        raise NotImplementedError


class ManagerNode:
    """Lock order: ``self.instance.lock``, then ``self.lock`` (the instance calls ``set_state`` and, on a freeze,
    ``get_state`` holding its lock). A reading is stored and published under both, so a freeze (the final state
    taken) falls between two readings: what the frozen instance published is exactly what its state says."""

    def __init__(self, p: ManagerParams, hooks: Callable[['ManagerNode', MeasurementStore], StoreHooks]) -> None:
        self.p = p
        self.grid = p.grid
        self.lock = threading.Lock()
        if p.reset_store:
            for path in (p.store, mark_path(p.store)):
                if os.path.exists(path):
                    os.replace(path, path + '.old')
                    rospy.loginfo(f'reset_store: moved the previous {path} to {path}.old')
        store = MeasurementStore(p.store, rospy.logwarn)
        for path in store.remove_stale_drafts():
            rospy.logwarn(f'removed {path}: a draft of the store left by an instance that ended before using it')
        self.ledger = Ledger(self.grid, store, p.standby_buffer, rospy.logwarn)
        self.migration = hooks(self, store)
        rospy.loginfo(f'{len(self.grid)} mapcells ({self.grid.cols} x {self.grid.rows} of {self.grid.cell_size:g} m); '
                      f'{self.ledger.count} stored measurements reloaded from {p.store}')
        self._dirty = True
        # the relay's receiving end (None: merged_measurements subscribed directly); its mark lies next to the store
        self.relay: Optional[Receiver] = Receiver(mark_path(p.store), p.relay.fsync) if p.relay else None
        self.relay_held = 0                             # batches not taken: not the active instance
        if self.relay is not None:
            rospy.loginfo(f'input: store-and-forward stream {p.relay.common.stream}; delivered mark '
                          f'{mark_path(p.store)}: epoch {self.relay.epoch}, up to seq {self.relay.delivered}')
        # what the relay replays makes the merger's retention unnecessary (README "Recovery")
        self.recover_proxy = (rospy.ServiceProxy(p.recover_service, GetRecentMeasurements)
                              if p.recover_service and self.relay is None else None)
        self.services: list = []
        self._constructed = threading.Event()          # on_active (instance thread) waits for the publishers
        self.instance: Optional[ManagedInstance] = None
        self.sub: Optional[rospy.Subscriber] = None
        # the instance first (a managed one's subscriptions must carry its host in their caller id); a standby
        # reports ready only once its merged_measurements subscription is connected (hooks.standby_ready), so the
        # manager never freezes the active instance before this one buffers what follows
        self.instance = ManagedInstance('local_mapcell_manager', self.migration)
        self.stop = threading.Event()
        if self.relay is None:
            self.sub = rospy.Subscriber('merged_measurements', MergedMeasurement, self._on_measurement,
                                        queue_size=100)
        else:
            self.ack_pub = rospy.Publisher(p.relay.common.topic('ack'), StoreForwardAck, queue_size=50)
            self.relay_sub = rospy.Subscriber(p.relay.common.topic('data'), StoreForwardBatch, self._on_batch,
                                              queue_size=50)
            rospy.on_shutdown(self.stop.set)
            threading.Thread(target=self._repeat_ack, name='relay_ack', daemon=True).start()
        # created now, used once active: subscribers are connected by the time the pending ones are published
        self.pub: Optional[rospy.Publisher] = self.instance.publisher('cell_states', CellStates, queue_size=1,
                                                                      latch=True)
        self.measurement_pub = self.instance.publisher('mapcell_measurements', MergedMeasurement, queue_size=100)
        rospy.Timer(rospy.Duration(p.publish_period), lambda _e: self._publish())
        self._constructed.set()
        if not self.instance.managed:
            self.migration.on_active()
        elif self.relay is not None:
            rospy.loginfo('managed: standby until promoted (the relay\'s batches are left to the sender)')
        else:
            rospy.loginfo('managed: standby until promoted (merged measurements are buffered, '
                          f'at most {p.standby_buffer})')

    # -- activation (the migration hooks are local_mapcell_manager.migration's) -----------------------
    def _recover(self, since: Optional[float]) -> List[Reading]:
        """The merger's retained measurements from ``since`` on (README "Recovery"); none if the buffer reaches
        back far enough (``since`` None), recovery is off, or the merger does not answer in time."""
        if since is None or self.recover_proxy is None:
            return []
        ok, res = call_with_timeout(self.recover_proxy, self.p.recover_timeout, rospy.Time.from_sec(since))
        if not ok and isinstance(res, rospy.ServiceException) and 'unavailable' in str(res):
            rospy.loginfo(f'{self.recover_proxy.resolved_name} is not advertised (no merger yet): nothing to recover')
            return []
        if not ok:
            rospy.logwarn(f'cannot recover the measurements published since {since:.3f} from '
                          f'{self.recover_proxy.resolved_name} ({type(res).__name__}: {res}): any that no store '
                          f'received are missing')
            return []
        if res.evicted and res.oldest_retained.to_sec() > since:
            rospy.logwarn(f'the merger no longer retains measurements from {since:.3f} to '
                          f'{res.oldest_retained.to_sec():.3f} (evicted: {res.evicted}): any of them that no store '
                          f'received are missing')
        return [r for r in map(self._reading, res.measurements) if r is not None]

    def _await_input(self, timeout: float) -> None:
        """Wait (at most ``timeout`` wall s) until ``merged_measurements`` is connected to a publisher before the
        merger's retained measurements are fetched: one published between that fetch and the connection (a store
        starting beside a running merger on a busy robot) would reach the store by neither way."""
        deadline = time.monotonic() + timeout
        while self.sub.get_num_connections() == 0 and time.monotonic() < deadline and not rospy.is_shutdown():
            time.sleep(0.05)

    @staticmethod
    def _recovered(since: Optional[float], recovered: List[Reading], added: int) -> str:
        if since is None:
            return ''
        return f'recovered {len(recovered)} retained measurement(s) since {since:.3f}, {added} not buffered; '

    def activate(self) -> None:
        """Store, publish and serve: a start or a promotion without a state takes up what the merger retained
        since its own newest measurement; the waiting measurements are published, then the cell states."""
        self._constructed.wait()
        if self.instance.managed and self.pub is None:     # active again after a freeze (rolled back)
            self.pub = self.instance.publisher('cell_states', CellStates, queue_size=1, latch=True)
        with self.lock:                                 # a promotion without a state: the own content's newest
            since = None if self.ledger.storing or self.relay is not None else \
                self.ledger.missing_since(self.ledger.newest_time)
        if since is not None and self.sub is not None:
            self._await_input(self.p.recover_timeout)
        recovered = self._recover(since)
        self.migration.discard_prepared()               # (promoted without a state: not used)
        with self.instance.lock, self.lock:
            own = self.ledger.count
            added = self.ledger.recover(recovered)      # nothing when already storing (no gap asked for)
            replay = self.ledger.activated()
            self._dirty = True
        if replay is not None and (self.instance.managed or recovered):
            rospy.loginfo(f'{"promoted without a state" if self.instance.managed else "started"}: {own} '
                          f'measurements of its own; {self._recovered(since, recovered, added)}'
                          f'{self._replayed(replay)}')
        with self.instance.lock:                        # the waiting measurements first: the hand-over's
            with self.lock:                             # output gap ends here
                self._flush()
                self._ack()                             # the relay sends what follows the mark (again)
            self._publish(force=True)

    def open_services(self) -> None:
        """``~get_cell``, ``~get_cell_states``, ``~get_measurements`` (they refuse while not active)."""
        if not self.services:                           # registrations with the master take a while
            self.services = [
                rospy.Service('~get_cell', GetCell, self._get_cell),
                rospy.Service('~get_cell_states', GetCellStates, self._get_cell_states),
                rospy.Service('~get_measurements', GetMeasurements, self._get_measurements)]

    def close_outputs(self) -> list:
        """Frozen: the latched cell_states publisher and the services, taken from the node (to be unregistered
        once the freeze was answered; under the instance's lock)."""
        with self.lock:
            self._sync_frozen()
            pub, self.pub = self.pub, None
            taken = [pub, *self.services]
            self.services = []
        return taken

    def _sync_frozen(self) -> None:
        """Under self.lock: a frozen instance stores nothing more and buffers again (a rollback may promote it
        again). Called where the instance's freeze is observed: in get_state, which the freeze calls holding
        the instance's lock, the final state is taken in the same step."""
        if self.instance.frozen and self.ledger.freeze():
            rospy.loginfo(f'frozen: {self.ledger.count} measurements handed over; buffering from now on')

    @staticmethod
    def _replayed(r: Replay) -> str:
        return (f'replayed {r.buffered} buffered measurement(s): {r.stored} new, {r.known} already stored, '
                f'{r.outside} outside the grid')

    # -- the relay (README "Input through the relay") ------------------------------------------------
    def _taking(self) -> bool:
        """Under both locks: may this instance take (store and acknowledge) the relay's batches now? Only the
        active one, storing: a standby, a frozen instance or one whose lease lapsed leaves them to the sender."""
        self._sync_frozen()
        return self.relay is not None and self.instance.active and self.ledger.storing

    def _ack(self) -> None:
        """Under both locks: acknowledge the delivered mark (active only; none before the first batch). Acks go
        out under the lock, in the order of the marks: a lower one after a higher one would make the sender go
        back."""
        if self._taking() and self.relay.epoch:
            self.ack_pub.publish(StoreForwardAck(stream=self.p.relay.common.stream, epoch=self.relay.epoch,
                                                 acked_seq=self.relay.delivered))

    def _repeat_ack(self) -> None:
        """Repeat the ack every ack_period while active: the sender learns at once that the link (or a newly
        promoted instance) is there, and where this instance's mark is."""
        self._constructed.wait()
        while not self.stop.wait(self.p.relay.ack_period) and not rospy.is_shutdown():
            try:
                with self.instance.lock, self.lock:
                    self._ack()
            except rospy.ROSException:
                if rospy.is_shutdown():
                    return
                raise

    @quiet_at_shutdown
    def _on_batch(self, batch: StoreForwardBatch) -> None:
        stream = self.p.relay.common.stream
        if batch.stream != stream or not batch.records:
            return
        if (batch.type, batch.md5sum) != (MergedMeasurement._type, MergedMeasurement._md5sum):
            rospy.logerr_throttle(10.0, f'store_forward stream {stream}: batches of {batch.type} ({batch.md5sum}), '
                                        f'not {MergedMeasurement._type}: not taken')
            return
        readings = [(r.seq, self._decode(r.data)) for r in batch.records]
        self._constructed.wait()
        with self.instance.lock, self.lock:
            if not self._taking():
                self.relay_held += 1
                return
            try:
                taken = take_batch(self.relay, self.ledger, batch.epoch, batch.acked_seq, readings)
            except OSError as exc:
                rospy.logerr_throttle(10.0, f'cannot store the relay\'s measurements ({exc}): not acknowledged, '
                                            f'they come again')
                return
            if taken.skipped:
                rospy.logwarn(f'store_forward stream {stream}: the sender no longer holds {taken.skipped} record(s) '
                              f'before seq {self.relay.delivered + 1}: any of them this store lacks are missing')
            if taken.duplicates:
                rospy.logwarn_throttle(5.0, f'ignored {self.ledger.duplicates} measurement(s) older than or equal '
                                            f'to the newest stored one (sent again by the relay)')
            if taken.stored:
                self._dirty = True
                self._flush()
            if taken.ack:
                self._ack()

    def _decode(self, data) -> Optional[Reading]:
        msg = MergedMeasurement()
        try:
            msg.deserialize(bytes(data))
        except Exception as exc:                     # genpy.DeserializationError, struct.error
            rospy.logerr_throttle(10.0, f'a relayed record is not a MergedMeasurement ({exc}): skipped')
            return None
        return self._reading(msg)

    # -- the stream --------------------------------------------------------------------------------
    @quiet_at_shutdown
    def _on_measurement(self, msg: MergedMeasurement) -> None:
        r = self._reading(msg)
        if r is None:
            return
        if self.instance is None:                      # still starting: the ledger only buffers
            with self.lock:
                self.ledger.receive(r)
            return
        with self.instance.lock, self.lock:
            self._sync_frozen()
            outcome, m = self.ledger.receive(r)
            if outcome == DUPLICATE:
                rospy.logwarn_throttle(5.0, f'ignored {self.ledger.duplicates} measurement(s) older than or equal '
                                            f'to the newest stored one (duplicates or out of order)')
            if m is not None:
                self._dirty = True
                if self.instance.active:
                    self._flush()

    @staticmethod
    def _reading(msg: MergedMeasurement) -> Optional[Reading]:
        values = (msg.x, msg.y, msg.temperature, msg.header.stamp.to_sec())
        if not all(math.isfinite(v) for v in values):
            rospy.logwarn_throttle(5.0, f'ignored a merged measurement with non-finite values {values}')
            return None
        return Reading(msg.header.stamp.to_sec(), msg.x, msg.y, msg.temperature, msg.pose_stamp.to_sec(), msg.yaw)

    def _flush(self) -> None:
        """Under both locks, while active: publish the stored measurements not published yet (a lapse, or the
        ones handed over or replayed at a promotion), in order."""
        if not self.instance.active:
            return
        pending = self.ledger.pending()
        for m, yaw in pending:
            self.measurement_pub.publish(self._measurement_msg(m, yaw))
        self.ledger.published(m.number for m, _ in pending)

    def _states(self) -> CellStates:
        with self.lock:
            msg = CellStates(rows=self.grid.rows, cols=self.grid.cols, cell_size=self.grid.cell_size,
                             cells=[cell_msg(self.grid, self.ledger.book, i) for i in range(len(self.grid))])
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = self.p.frame_id
        return msg

    @quiet_at_shutdown
    def _publish(self, force: bool = False) -> None:
        with self.instance.lock:
            if self.pub is None or not self.instance.active:
                return
            if self._dirty or force:
                self._dirty = False
                self.pub.publish(self._states())

    def _measurement_msg(self, m: Measurement, yaw: float = math.nan) -> MergedMeasurement:
        """A stored measurement as a message: its cell filled, its store number in header.seq."""
        mm = MergedMeasurement(x=m.x, y=m.y, yaw=yaw, temperature=m.temperature,
                               pose_stamp=rospy.Time.from_sec(m.pose_time),
                               stamp_difference=abs(m.time - m.pose_time), cell=m.cell)
        mm.header.stamp = rospy.Time.from_sec(m.time)
        mm.header.frame_id = self.p.frame_id
        mm.header.seq = m.number
        return mm

    # -- services (only while active) --------------------------------------------------------------
    def _get_cell(self, req) -> GetCellResponse:
        if not self.instance.active:
            raise rospy.ServiceException(NOT_ACTIVE)
        index = self.grid.index_of(req.x, req.y)
        if index is None:
            return GetCellResponse(found=False)
        with self.lock:
            return GetCellResponse(found=True, cell=cell_msg(self.grid, self.ledger.book, index))

    def _get_cell_states(self, _req) -> GetCellStatesResponse:
        if not self.instance.active:
            raise rospy.ServiceException(NOT_ACTIVE)
        return GetCellStatesResponse(self._states())

    def _get_measurements(self, req) -> GetMeasurementsResponse:
        if not self.instance.active:
            return GetMeasurementsResponse(success=False, message=NOT_ACTIVE)
        if req.cell_index != -1 and not 0 <= req.cell_index < len(self.grid):
            return GetMeasurementsResponse(success=False, message=f'no cell {req.cell_index} '
                                                                   f'(0..{len(self.grid) - 1} or -1 for all)')
        with self.lock:
            ms = self.ledger.measurements(None if req.cell_index == -1 else req.cell_index)
        out = [self._measurement_msg(m) for m in ms]
        return GetMeasurementsResponse(success=True, message=f'{len(out)} measurements', measurements=out)

