"""The ``sender`` node (robot side): store every message of the input topic on disk, send it to the receiver
until acknowledged (see the package README).

ROS I/O and one loop thread; the queue and the protocol are in :mod:`cnr_store_forward.core`. Nothing here
waits on the cloud: publishing is queued (rospy drops a batch the link cannot take; it is sent again), the
loop runs on the monotonic clock, and the only blocking calls are local disk writes.
"""
from __future__ import annotations

import math
import threading
import time
from typing import List, Tuple

import rospy

from cnr_msgs.msg import StoreForwardAck, StoreForwardBatch, StoreForwardRecord, StoreForwardStatus
from cnr_params import exit_on_config_error
from cnr_params.ros import private_section
from cnr_runtime import init_node
from cnr_store_forward.core import config as sf_config
from cnr_store_forward.core.queue import DiskQueue, QueueError, Record
from cnr_store_forward.core.sender import Sender
from cnr_store_forward.wire import RELAY_HEADER, ros_time



class SenderNode:
    def __init__(self, cfg: sf_config.SenderConfig) -> None:
        self.cfg = cfg
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.failed = ''
        self.closed = False
        self.queue = q = DiskQueue(cfg.stream_dir, cfg.max_records, cfg.max_bytes, cfg.segment_bytes, cfg.fsync,
                                   cfg.retain_records)
        r = q.recovery
        pending = f'seq {q.acked + 1}..{q.last_seq} unacked' if q.unacked else f'next seq {q.last_seq + 1}'
        rospy.loginfo(f'store_forward sender {cfg.common.stream}: queue {cfg.stream_dir} '
                      f'({"new" if r.created else "reopened"}, epoch {q.epoch}): {r.records} records in '
                      f'{r.segments} segment(s), {pending}')
        if r.torn_bytes:
            rospy.logwarn(f'store_forward sender {cfg.common.stream}: cut a torn tail of {r.torn_bytes} bytes '
                          f'(a write interrupted by a crash; the records before it are intact)')
        if r.skipped_to:
            rospy.logwarn(f'store_forward sender {cfg.common.stream}: the acked mark was ahead of the records on '
                          f'disk (lost without fsync); sequence numbers continue at {r.skipped_to}')
        self.sender = Sender(self.queue, cfg.settings)
        self.type_rejected = 0
        self.ignored = 0
        self.reported_full = False
        meta = self.queue.meta
        self.type: Tuple[str, str] = (meta.get('type', ''), meta.get('md5sum', ''))
        # rospy holds up to a window of batches per connection while the link is slow, then drops the oldest
        # (sent again after the ack timeout)
        window_batches = -(-cfg.settings.window // cfg.settings.batch_records)
        self.data_pub = rospy.Publisher(cfg.common.topic('data'), StoreForwardBatch, queue_size=window_batches + 1)
        self.status_pub = rospy.Publisher('~status', StoreForwardStatus, queue_size=5)
        rospy.Subscriber(cfg.common.topic('ack'), StoreForwardAck, self.on_ack, queue_size=50)
        # unbounded: a message is never dropped before it is on disk
        rospy.Subscriber(cfg.input_topic, rospy.AnyMsg, self.on_input, queue_size=None)

    # ---------------------------------------------------------------- input and acks
    def on_input(self, msg: rospy.AnyMsg) -> None:
        header = msg._connection_header
        if RELAY_HEADER in header:
            with self.lock:
                self.ignored += 1
                first = self.ignored == 1
            if first:
                rospy.logwarn(f'store_forward sender {self.cfg.common.stream}: ignoring {self.cfg.input_topic} from '
                              f'{header.get("callerid")}, the receiver of stream {header[RELAY_HEADER]}: relayed '
                              f'messages are never relayed again (is the topic bridged back to this master?)')
            return
        kind = (header.get('type', ''), header.get('md5sum', ''))
        stamp = time.time_ns()
        with self.lock:
            if self.closed:
                return
            if kind != self.type:
                if self.queue.unacked:
                    self.type_rejected += 1
                    rospy.logerr_throttle(10.0, f'store_forward sender {self.cfg.common.stream}: refusing '
                                                f'{kind[0]} from {header.get("callerid")}: the queue holds '
                                                f'{self.type[0]} ({self.type_rejected} refused)')
                    return
                self.queue.set_meta({'type': kind[0], 'md5sum': kind[1],
                                     'message_definition': header.get('message_definition', '')})
                self.type = kind
            try:
                self.queue.append(bytes(msg._buff), stamp)
            except OSError as exc:
                rospy.logerr_throttle(10.0, f'store_forward sender {self.cfg.common.stream}: cannot store a '
                                            f'record: {exc.strerror or exc} ({self.queue.rejected} refused)')
                return
            if self.cfg.sync_period == 0.0:
                self.queue.sync()
            self.report_full()

    def on_ack(self, msg: StoreForwardAck) -> None:
        if msg.stream != self.cfg.common.stream:
            return
        with self.lock:
            if self.closed:
                return
            rewinds = self.sender.rewinds
            self.sender.on_ack(msg.epoch, msg.acked_seq, time.monotonic())
            if self.sender.rewinds != rewinds:
                rospy.loginfo(f'store_forward sender {self.cfg.common.stream}: {msg._connection_header.get("callerid")} '
                              f'acknowledged up to seq {msg.acked_seq} only: sending from seq '
                              f'{self.sender.base + 1} again')
            self.report_full()

    def report_full(self) -> None:
        """Log a change of the queue's full flag (caller holds the lock)."""
        q = self.queue
        if q.full == self.reported_full:
            return
        self.reported_full = q.full
        if q.full:
            rospy.logerr(f'store_forward sender {self.cfg.common.stream}: queue FULL ({q.unacked} records, '
                         f'{q.unacked_bytes} bytes; bounds {q.max_records} records, {q.max_bytes} bytes): new '
                         f'records are refused until the receiver acknowledges')
        else:
            rospy.logwarn(f'store_forward sender {self.cfg.common.stream}: queue has room again; '
                          f'{q.rejected} records refused so far')

    # ---------------------------------------------------------------- sending
    def batch(self, records: List[Record]) -> StoreForwardBatch:
        return StoreForwardBatch(
            stream=self.cfg.common.stream, epoch=self.queue.epoch, acked_seq=self.queue.floor,
            type=self.type[0], md5sum=self.type[1],
            records=[StoreForwardRecord(seq=r.seq, stamp=ros_time(r.stamp_ns), data=r.data) for r in records])

    def status(self) -> StoreForwardStatus:
        q, s = self.queue, self.sender
        age = math.nan
        if s.pending:
            age = (time.time_ns() - q.stamp_of(s.base + 1)) / 1e9
        msg = StoreForwardStatus(
            stream=self.cfg.common.stream, role=StoreForwardStatus.SENDER, epoch=q.epoch, type=self.type[0],
            last_seq=q.last_seq, acked_seq=s.base, queued=s.pending, queued_bytes=q.unacked_bytes,
            in_flight=s.in_flight, appended=q.appended, sent=s.sent, resent=s.resent, timeouts=s.timeouts, full=q.full,
            rejected=q.rejected + self.type_rejected, ignored=self.ignored, oldest_unacked_age=age)
        msg.header.stamp = ros_time(time.time_ns())
        return msg

    def tick(self, now: float, sync: bool, status: bool) -> None:
        with self.lock:
            if self.closed:
                return
            if sync:
                self.queue.sync()
            records = self.sender.poll(now)
            batch = self.batch(records) if records else None
            report = self.status() if status else None
        if batch is not None:
            self.data_pub.publish(batch)
        if report is not None:
            self.status_pub.publish(report)

    def run(self) -> None:
        cfg = self.cfg
        period = 1.0 / cfg.rate
        now = time.monotonic()
        next_tick = next_sync = next_status = now
        while not rospy.is_shutdown() and not self.stop.wait(max(0.0, next_tick - time.monotonic())):
            now = time.monotonic()
            sync, status = now >= next_sync, now >= next_status
            try:
                self.tick(now, sync, status)
            except (QueueError, OSError) as exc:
                self.failed = f'store_forward sender {cfg.common.stream}: {exc}'
                rospy.logfatal(self.failed)
                rospy.signal_shutdown('queue failure')
                return
            except rospy.ROSException:
                if rospy.is_shutdown():
                    return
                raise
            if sync:
                next_sync = max(next_sync + cfg.sync_period, now)
            if status:
                next_status = max(next_status + 1.0 / cfg.common.status_rate, now)
            next_tick = max(next_tick + period, now)

    def close(self) -> None:
        self.stop.set()
        with self.lock:
            if not self.closed:
                self.closed = True
                self.queue.sync()
                self.queue.close()


@exit_on_config_error
def main() -> None:
    init_node('store_forward_sender')
    cfg = sf_config.sender_from_section(private_section())
    try:
        node = SenderNode(cfg)
    except (QueueError, OSError) as exc:
        rospy.logfatal(f'store_forward sender {cfg.common.stream}: cannot open the queue: {exc}')
        raise SystemExit(1) from None
    rospy.on_shutdown(node.stop.set)
    try:
        node.run()
    finally:
        node.close()
    if node.failed:
        raise SystemExit(1)
