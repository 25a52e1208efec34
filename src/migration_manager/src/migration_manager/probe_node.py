"""``migration_probe``: the consumer's view of a module across migrations (tests and bench_migration.sh).

Records every message of the given topics with its arrival time (wall clock, this host) and the instance that
published it (the ``cnr_instance`` connection header; '-' for an unmanaged publisher), and optionally calls
``/global_goal_manager/next_goal`` at a fixed rate over a persistent connection that, after a failed or refused
request, waits for the name to move to another provider (:class:`migration_manager.client.MovableServiceProxy`;
the global goal manager has no periodic output of its own), recording each answer at the time its request went
out (a request sent then was served; a call that failed holds why in the instance column), and move_base's goal
results (``/move_base/result``: ok = succeeded, the
final status code in the instance column). For the modules in ``~status_modules`` it also records when each instance closed its outputs for good (topic ``frozen``: the
frozen status's stamp, the instance's own clock — on the testbed one clock for every host), when one became
active (topic ``active``: a promotion, or a renewal granted again after a lapse) and when an active one's lease
lapsed (topic ``lapsed``), both stamped by the instance. Writes a TSV
(``time``, ``topic``, ``instance``, ``ok``, ``stamp``: the message's header stamp for a type with a header, so an
output can be matched with the input it carries) as it goes, flushed per line, so a reader sees the gaps: the
consumer's gap (last output of the old instance to the first of the new one) and the downtime (the old
instance's outputs closed to the new one's first output arriving here; for a store, how long a measurement
waited for one).
"""
from __future__ import annotations

import struct
import threading
import time
from typing import Dict

import rospy
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseActionResult

import cnr_params
from cnr_msgs.msg import InstanceStatus
from cnr_msgs.srv import NextGoal
from cnr_params.ros import private_section
from cnr_runtime import init_node
from migration_manager.client import MovableServiceProxy
from migration_manager.instance import INSTANCE_HEADER


class Probe:
    def __init__(self) -> None:
        p = private_section('~')
        topics = p.raw('topics')
        if not isinstance(topics, list) or not all(isinstance(t, str) and t for t in topics):
            raise p.error('topics', f'must be a list of topic names, got {topics!r}')
        self.rate = p.number('next_goal_rate', nonnegative=True)
        modules = p.raw('status_modules')
        if not isinstance(modules, list) or not all(isinstance(m, str) and m for m in modules):
            raise p.error('status_modules', f'must be a list of module names, got {modules!r}')
        hosts = p.raw('hosts')
        if not isinstance(hosts, list) or not all(isinstance(h, str) and h for h in hosts):
            raise p.error('hosts', f'must be a list of host names, got {hosts!r}')
        self.frozen_seen = set()
        self.roles: Dict[tuple, int] = {}          # (instance, pid, term) -> its newest role
        self.lock = threading.Lock()
        self.out = open(p.string('out'), 'a', buffering=1)
        if self.out.tell() == 0:
            self.out.write('time\ttopic\tinstance\tok\tstamp\n')
        self.stamped: Dict[str, bool] = {}         # message type -> its first field is a std_msgs/Header
        for t in topics:
            rospy.Subscriber(t, rospy.AnyMsg, self._on_msg, callback_args=t, queue_size=200)
        # move_base's results: ok = SUCCEEDED, the instance column holds the final status
        rospy.Subscriber('/move_base/result', MoveBaseActionResult, self._on_result, queue_size=20)
        for m in modules:
            for h in hosts:
                rospy.Subscriber(f'/migration/{m}/{h}/status', InstanceStatus, self._on_status, queue_size=20)
        # persistent; after a failed or refused request it waits for the name to move (migration_manager.client)
        self.next_goal = MovableServiceProxy('/global_goal_manager/next_goal', NextGoal)
        self.last_instance = ''

    def _write(self, topic: str, instance: str, ok: bool, at: float = 0.0, stamp: str = '') -> None:
        with self.lock:
            self.out.write(f'{at or time.time():.6f}\t{topic}\t{instance}\t{int(ok)}\t{stamp}\n')

    def _stamp(self, msg: rospy.AnyMsg) -> str:
        """The header stamp of a serialized message whose type starts with a Header ('' otherwise)."""
        kind = msg._connection_header.get('type', '')
        if kind not in self.stamped:
            from roslib.message import get_message_class
            cls = get_message_class(kind)
            self.stamped[kind] = bool(cls is not None and cls._slot_types[:1] == ['std_msgs/Header'])
        if not self.stamped[kind] or len(msg._buff) < 12:
            return ''
        _seq, secs, nsecs = struct.unpack_from('<III', msg._buff)
        return f'{secs}.{nsecs:09d}'

    def _on_status(self, msg: InstanceStatus) -> None:
        key = (msg.instance, msg.pid, msg.term)
        if msg.role == InstanceStatus.FROZEN and key not in self.frozen_seen:
            self.frozen_seen.add(key)
            self._write('frozen', msg.instance, True, msg.header.stamp.to_sec())
        # active: the outputs opened (a promotion, or a renewal granted again after a lapse); lapsed: an active
        # instance's lease ran out (its outputs closed until a renewal is granted). Stamped by the instance.
        before = self.roles.get(key)
        self.roles[key] = msg.role
        if msg.role == InstanceStatus.ACTIVE and before != InstanceStatus.ACTIVE:
            self._write('active', msg.instance, True, msg.header.stamp.to_sec())
        elif msg.role == InstanceStatus.PROMOTED and before == InstanceStatus.ACTIVE:
            self._write('lapsed', msg.instance, False, msg.header.stamp.to_sec())

    def _on_msg(self, msg: rospy.AnyMsg, topic: str) -> None:
        self._write(topic, msg._connection_header.get(INSTANCE_HEADER, '-'), True, stamp=self._stamp(msg))

    def _on_result(self, msg: MoveBaseActionResult) -> None:
        self._write('/move_base/result', str(msg.status.status), msg.status.status == GoalStatus.SUCCEEDED)

    def spin(self) -> None:
        if self.rate <= 0:
            rospy.spin()
            return
        period = 1.0 / self.rate
        next_call = time.monotonic()
        while not rospy.core.is_shutdown_requested():
            ok, answer, sent = self.next_goal.call(1.0, 0.0, 0.0)
            self._write('next_goal', '' if ok else why_failed(answer), ok, sent)
            next_call = max(next_call + period, time.monotonic())
            time.sleep(max(0.0, next_call - time.monotonic()))


def why_failed(result) -> str:
    """A failed call's refusal or exception in one short TSV-safe field (for a post-mortem of the probe's file)."""
    text = getattr(result, 'message', '') or f'{type(result).__name__}: {result}'
    return ' '.join(str(text).split())[:120]


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('migration_probe')
    Probe().spin()
