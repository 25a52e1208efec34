"""The client and monitor nodes of the thesis's RTT experiment (Table 4-1, Appendix II).

``echo_monitor`` answers on a topic (``rtt/ping`` -> ``rtt/pong``, std_msgs/Header) and a service
(``rtt/echo``, cnr_msgs/Echo). ``echo_client`` measures the wall-clock round trip of ``~samples``
probes, ``~interval`` seconds apart, in one ``~mode``:

* ``topic``: publish a Header, wait for the same seq on ``rtt/pong``;
* ``service``: the naive client: one non-persistent ``rospy.ServiceProxy``, which looks the service
  up at the master and opens a new connection on every call (what the thesis measured);
* ``service_persistent``: a persistent ServiceProxy (the thesis's own recommendation).

Results go to stdout and, if ``~output`` is set, to a TSV file (``seq<TAB>rtt_ms``), appended
atomically at the end.
"""
from __future__ import annotations

import threading
import time
from typing import List

import rospy
from std_msgs.msg import Header

from cnr_msgs.srv import Echo, EchoResponse
from cnr_params import exit_on_config_error
from cnr_params.files import write_atomic
from cnr_params.ros import private_section
from cnr_runtime import init_node

MODES = ('topic', 'service', 'service_persistent')


@exit_on_config_error
def monitor_main() -> None:
    init_node('echo_monitor')
    pong = rospy.Publisher('rtt/pong', Header, queue_size=10, tcp_nodelay=True)
    rospy.Subscriber('rtt/ping', Header, pong.publish, queue_size=10, tcp_nodelay=True)
    rospy.Service('rtt/echo', Echo, lambda req: EchoResponse(seq=req.seq, stamp=req.stamp))
    rospy.loginfo('echo_monitor ready: rtt/ping -> rtt/pong, service rtt/echo')
    rospy.spin()


class _TopicProbe:
    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._seen = -1
        self.pub = rospy.Publisher('rtt/ping', Header, queue_size=10, tcp_nodelay=True)
        self.sub = rospy.Subscriber('rtt/pong', Header, self._on_pong, queue_size=10, tcp_nodelay=True)

    def _on_pong(self, msg: Header) -> None:
        with self._cond:
            self._seen = msg.seq
            self._cond.notify_all()

    def connected(self) -> bool:
        return self.pub.get_num_connections() > 0 and self.sub.get_num_connections() > 0

    def probe(self, seq: int, timeout: float) -> float:
        start = time.perf_counter()
        with self._cond:
            self.pub.publish(Header(seq=seq))
            if not self._cond.wait_for(lambda: self._seen == seq, timeout):
                return float('nan')
        return (time.perf_counter() - start) * 1000.0


@exit_on_config_error
def client_main() -> None:
    init_node('echo_client')
    p = private_section('~')
    mode = p.string('mode', choices=MODES)
    samples = p.integer('samples', minimum=1)
    interval = p.number('interval', nonnegative=True)
    timeout = p.number('timeout', positive=True)
    output = p.string('output')
    rtts: List[float] = []
    if mode == 'topic':
        probe = _TopicProbe()
        deadline = time.monotonic() + 60.0
        while not probe.connected():
            if time.monotonic() > deadline or rospy.is_shutdown():
                rospy.logfatal('echo_client: no echo_monitor connected on rtt/ping and rtt/pong')
                raise SystemExit(1)
            time.sleep(0.01)
        probe.probe(0, timeout)   # warm-up: the first message also carries the connection header
        call = lambda seq: probe.probe(seq, timeout)  # noqa: E731
    else:
        rospy.wait_for_service('rtt/echo', timeout=60.0)
        proxy = rospy.ServiceProxy('rtt/echo', Echo, persistent=(mode == 'service_persistent'))
        proxy(seq=0, stamp=rospy.Time(0))   # warm-up

        def call(seq: int) -> float:
            start = time.perf_counter()
            proxy(seq=seq, stamp=rospy.Time(0))
            return (time.perf_counter() - start) * 1000.0
    for seq in range(1, samples + 1):
        if rospy.is_shutdown():
            break
        try:
            rtt = call(seq)
        except rospy.ServiceException as exc:
            rospy.logwarn('echo_client: call %d failed: %s', seq, exc)
            rtt = float('nan')
        rtts.append(rtt)
        print(f'{mode} sample {seq}/{samples}: {rtt:.2f} ms', flush=True)
        time.sleep(interval)
    if output:
        write_atomic(output, 'seq\trtt_ms\n' + ''.join(f'{i}\t{r:.3f}\n' for i, r in enumerate(rtts, 1)))
    raise SystemExit(0 if rtts and all(r == r for r in rtts) else 1)
