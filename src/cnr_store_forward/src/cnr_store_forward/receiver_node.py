"""The ``receiver`` node (cloud side): deliver each record of a stream once and in order on the output topic,
as the original message, and acknowledge it (see the package README).

ROS I/O only; the protocol is in :mod:`cnr_store_forward.core.receiver`. The records are republished as
their original serialized bytes under their original type (no deserialization): the publisher's class is
built from the type and MD5 sum the batch names. Publishing is synchronous (the message is in the
consumer's TCP connection when publish returns), then the mark is persisted, then the ack is sent.
"""
from __future__ import annotations

import math
import os
import threading
import time
import warnings
from typing import Optional, Tuple, Type

import rospy

from cnr_msgs.msg import StoreForwardAck, StoreForwardBatch, StoreForwardStatus
from cnr_params import exit_on_config_error
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from cnr_store_forward.core import config as sf_config
from cnr_store_forward.core.receiver import Receiver
from cnr_store_forward.wire import RELAY_HEADER, raw_message, raw_message_class, ros_time


class ReceiverNode:
    def __init__(self, cfg: sf_config.ReceiverConfig) -> None:
        self.cfg = cfg
        self.lock = threading.Lock()
        self.stop = threading.Event()
        os.makedirs(cfg.state_dir, exist_ok=True)
        self.receiver = Receiver(cfg.state_path, cfg.fsync)
        rospy.loginfo(f'store_forward receiver {cfg.common.stream}: state {cfg.state_path}: epoch '
                      f'{self.receiver.epoch}, delivered up to seq {self.receiver.delivered}')
        self.kind: Tuple[str, str] = ('', '')
        self.out_class: Optional[Type[rospy.AnyMsg]] = None
        self.out_pub: Optional[rospy.Publisher] = None
        self.held = 0
        self.seen = (0, 0)          # (epoch, sender's ack) of the newest batch, for the repeated ack
        self.ack_pub = rospy.Publisher(cfg.common.topic('ack'), StoreForwardAck, queue_size=50)
        self.status_pub = rospy.Publisher('~status', StoreForwardStatus, queue_size=5)
        if self.receiver.kind[0]:
            with self.lock:
                self.output(self.receiver.kind)     # advertised now: the consumer connects before data comes
        rospy.Subscriber(cfg.common.topic('data'), StoreForwardBatch, self.on_batch, queue_size=50)

    def output(self, kind: Tuple[str, str]) -> rospy.Publisher:
        """The output publisher for messages of ``kind`` (type, md5sum), (re)created when the type changes."""
        if kind != self.kind or self.out_pub is None:
            if self.out_pub is not None:
                rospy.logwarn(f'store_forward receiver {self.cfg.common.stream}: the stream changed type from '
                              f'{self.kind[0]} to {kind[0]}')
                self.out_pub.unregister()
            self.out_class = raw_message_class(*kind)
            with warnings.catch_warnings():
                # synchronous on purpose: publish() returns once the message is in the consumer's connection
                warnings.simplefilter('ignore', SyntaxWarning)
                self.out_pub = rospy.Publisher(self.cfg.output_topic, self.out_class, queue_size=None,
                                               headers={RELAY_HEADER: self.cfg.common.stream})
            self.kind = kind
            self.receiver.set_kind(kind)
            if not self.out_class._full_text:
                rospy.logwarn(f'store_forward receiver {self.cfg.common.stream}: no local definition of '
                              f'{kind[0]} ({kind[1]}); republishing without one')
        return self.out_pub

    @quiet_at_shutdown
    def on_batch(self, batch: StoreForwardBatch) -> None:
        if batch.stream != self.cfg.common.stream or not batch.type:
            return
        with self.lock:
            self.seen = (batch.epoch, batch.acked_seq)
            pub = self.output((batch.type, batch.md5sum))
            if self.cfg.require_consumer and pub.get_num_connections() == 0:
                self.held += 1
                return
            records = batch.records
            plan = self.receiver.plan(batch.epoch, batch.acked_seq, [r.seq for r in records])
            published = 0
            try:
                for r in records[plan.start:]:
                    pub.publish(raw_message(self.out_class, r.data))
                    published = r.seq
            finally:                        # also when publishing fails at shutdown: commit what went out
                if published:
                    self.commit(published)
            if plan.ack:                    # under the lock: acks go out in the order of the marks they carry
                self.ack_pub.publish(self.ack())

    def ack(self) -> StoreForwardAck:
        return StoreForwardAck(stream=self.cfg.common.stream, epoch=self.receiver.epoch,
                               acked_seq=self.receiver.delivered)

    def keepalive(self) -> None:
        """Repeat the ack while there is a consumer: after an outage (or while the first batches were held
        for want of a consumer) the sender learns at once that it can send, instead of waiting out its backoff.
        For an epoch the receiver has not accepted a batch of yet, the ack repeats the sender's own ack (no
        progress, it only ends the backoff)."""
        with self.lock:
            ready = self.out_pub is not None and (not self.cfg.require_consumer
                                                  or self.out_pub.get_num_connections() > 0)
            epoch, sender_ack = self.seen
            ack = None
            if ready and epoch and epoch not in self.receiver.retired and epoch != self.receiver.epoch:
                ack = StoreForwardAck(stream=self.cfg.common.stream, epoch=epoch, acked_seq=sender_ack)
            elif ready and self.receiver.epoch:
                ack = self.ack()
            if ack is not None:             # (a lower ack after a higher one would make the sender go back)
                self.ack_pub.publish(ack)

    def commit(self, seq: int) -> None:
        try:
            self.receiver.commit(seq)
        except OSError as exc:              # delivered all the same; a restart would deliver them again
            rospy.logerr_throttle(10.0, f'store_forward receiver {self.cfg.common.stream}: cannot save '
                                        f'{self.cfg.state_path}: {exc.strerror or exc}')

    def status(self) -> StoreForwardStatus:
        with self.lock:
            r = self.receiver
            connected = self.out_pub is not None and self.out_pub.get_num_connections() > 0
            msg = StoreForwardStatus(
                stream=self.cfg.common.stream, role=StoreForwardStatus.RECEIVER, epoch=r.epoch, type=self.kind[0],
                last_seq=r.last_seq, acked_seq=r.delivered, oldest_unacked_age=math.nan,
                delivered=r.delivered_count, duplicates=r.duplicates, out_of_order=r.out_of_order, stale=r.stale,
                consumer_connected=connected, held=self.held)
        msg.header.stamp = ros_time(time.time_ns())
        return msg

    def run(self) -> None:
        status_period, ack_period = 1.0 / self.cfg.common.status_rate, self.cfg.ack_period
        next_status = next_ack = time.monotonic()
        while not rospy.is_shutdown() and \
                not self.stop.wait(max(0.0, min(next_status, next_ack) - time.monotonic())):
            now = time.monotonic()
            try:
                if now >= next_ack:
                    self.keepalive()
                    next_ack = max(next_ack + ack_period, now)
                if now >= next_status:
                    self.status_pub.publish(self.status())
                    next_status = max(next_status + status_period, now)
            except rospy.ROSException:
                if rospy.is_shutdown():
                    return
                raise


@exit_on_config_error
def main() -> None:
    init_node('store_forward_receiver')
    cfg = sf_config.receiver_from_section(private_section())
    try:
        node = ReceiverNode(cfg)
    except OSError as exc:
        rospy.logfatal(f'store_forward receiver {cfg.common.stream}: cannot use {cfg.state_dir}: '
                       f'{exc.strerror or exc}')
        raise SystemExit(1) from None
    rospy.on_shutdown(node.stop.set)
    node.run()
