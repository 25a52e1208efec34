"""The ROS side of bench_profile: runs inside the testbed's robot namespace on the robot's master.

    python3 -m cnr_benchmarks.profile_worker --testbed-config C --testbed-name N --cells 0:0,20:1 --reps 2
        --out profile.tsv --load-fraction 0.5 --load-hz 20 --passive-age 10
    python3 -m cnr_benchmarks.profile_worker --sink        # on the cloud: subscribes the background load

Started by :mod:`cnr_benchmarks.profile_bench`, which brings up the testbed, both masters, the bridges and a
network_monitor on each host. Per cell it sets the link through the emulator's control socket (one-way delay
RTT/2 and the rate on both directions), then per repetition:

1. RTT: waits for a profile of the robot's monitor stamped at least ``window`` s (the monitor's echo window,
   read from its parameters) after the link was set or the last traffic stopped, so that every ping in the
   window saw the new setting and an idle link; takes its ``rtt`` (median) and ``rtt_spread``.
2. probe: ``~profile_now`` with ``probe: true`` (the monitor's ``probe_method``: an iperf3 stream or a packet
   train); A_bw from the answer, the caller's wall time, the bytes the probe reports sent (the profile's
   ``probe_bytes`` difference: iperf3's count or the train's packets) and the bytes the emulator delivered in
   each direction meanwhile (its ``bytes_delivered`` counters; pings and bridge heartbeats, a few kB/s,
   included).
3. passive (shaped cells only): publishes ``load_fraction`` x rate as ``load_hz`` messages per second on
   ``/bench_profile/load`` (std_msgs/UInt8MultiArray, to the sink on the cloud, across the bridge) from the end
   of the probe, and takes the first profile whose ``a_bw_age`` is at least ``passive_age`` s.

One TSV row per repetition (columns of :class:`cnr_benchmarks.core.profile.Sample`), progress on stdout.
"""
from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from typing import Callable, List, Optional, Tuple

LOAD_TOPIC = '/bench_profile/load'
MONITOR = '/network_monitor'
READY_TIMEOUT = 120.0


def parse_cells(text: str) -> List[Tuple[float, float]]:
    """``'0:0,20:1'`` -> ``[(0.0, 0.0), (20.0, 1.0)]`` (RTT ms : rate Mbit/s, 0 = unshaped)."""
    return [(float(a), float(b)) for a, b in (cell.split(':') for cell in text.split(','))]


class Latest:
    """The newest message on a topic, and waiting for one that satisfies a condition."""

    def __init__(self, topic: str, msg_type) -> None:
        import rospy
        self.msg = None
        self.sub = rospy.Subscriber(topic, msg_type, self._store, queue_size=10)

    def _store(self, msg) -> None:
        self.msg = msg

    def wait(self, condition: Callable, timeout: float, what: str):
        from cnr_harness import wait_until
        return wait_until(lambda: self.msg if self.msg is not None and condition(self.msg) else None,
                          timeout, what, interval=0.02)


class Load:
    """Background traffic: messages of ``rate / hz`` bytes at ``hz`` per second while started."""

    def __init__(self, topic: str, hz: float) -> None:
        import rospy
        from std_msgs.msg import UInt8MultiArray
        self.msg_type = UInt8MultiArray
        self.pub = rospy.Publisher(topic, UInt8MultiArray, queue_size=2)
        self.hz = hz
        self.payload: Optional[bytes] = None
        self.stop_event = threading.Event()
        threading.Thread(target=self._loop, daemon=True).start()

    def start(self, bits_per_second: float) -> None:
        self.payload = bytes(max(1, int(bits_per_second / 8.0 / self.hz)))

    def stop(self) -> None:
        self.payload = None

    def _loop(self) -> None:
        period = 1.0 / self.hz
        deadline = time.monotonic()
        while not self.stop_event.wait(max(0.0, deadline - time.monotonic())):
            payload = self.payload
            if payload is not None:
                self.pub.publish(self.msg_type(data=payload))
            deadline = max(deadline + period, time.monotonic() - period)


def run_sink() -> int:
    import rospy
    from std_msgs.msg import UInt8MultiArray
    rospy.init_node('bench_profile_sink')
    rospy.Subscriber(LOAD_TOPIC, UInt8MultiArray, lambda _msg: None, queue_size=2)
    rospy.spin()
    return 0


def link_bytes(tb) -> Tuple[int, int]:
    st = tb.status()
    return st['up']['counters']['bytes_delivered'], st['down']['counters']['bytes_delivered']


def run(args: argparse.Namespace) -> int:
    import rospy
    from cnr_msgs.msg import NetworkProfile
    from cnr_msgs.srv import ProfileNow
    from cnr_benchmarks.core.profile import Sample
    from cnr_benchmarks.report import TsvLog, progress
    from cnr_testbed.api import Testbed
    from cnr_testbed.cli import overrides
    from network_monitor.codes import A_BW_METHOD_WORD

    rospy.init_node('bench_profile')
    tb = Testbed(args.testbed_config, overrides(args.testbed_name))    # the running instance's control socket
    rospy.wait_for_service(f'{MONITOR}/profile_now', timeout=READY_TIMEOUT)     # its parameters are loaded
    name = rospy.get_param(f'{MONITOR}/name')
    window = float(rospy.get_param(f'{MONITOR}/window'))
    profiles = Latest(f"{rospy.get_param(f'{MONITOR}/topic_prefix')}/{name}/network_profile", NetworkProfile)
    load = Load(LOAD_TOPIC, args.load_hz)
    profile_now = rospy.ServiceProxy(f'{MONITOR}/profile_now', ProfileNow)
    profiles.wait(lambda m: m.alive and math.isfinite(m.rtt), READY_TIMEOUT,
                  'an alive profile (echo across the bridge)')
    from cnr_harness import wait_until
    wait_until(lambda: load.pub.get_num_connections() > 0, READY_TIMEOUT, 'the load sink on the cloud')
    log = TsvLog(args.out, Sample.columns())
    try:
        for rtt, rate in parse_cells(args.cells):
            tb.set('both', delay=rtt / 2.0, rate=rate)
            quiet = time.time()
            for rep in range(1, args.reps + 1):
                p = profiles.wait(lambda m: m.header.stamp.to_sec() >= quiet + window and math.isfinite(m.rtt),
                                  window + 30.0, f'a profile {window:g} s after the link went quiet')
                before_bytes, before_link = p.probe_bytes, link_bytes(tb)
                t0 = time.monotonic()
                answer = profile_now(probe=True)
                probe_s = time.monotonic() - t0
                answered = time.time()
                after_link = link_bytes(tb)
                passive = None
                if rate > 0 and answer.success:
                    load.start(args.load_fraction * rate * 1e6)
                    try:
                        passive = profiles.wait(lambda m: m.header.stamp.to_sec() >= answered
                                                and m.a_bw_age >= args.passive_age, args.passive_age + 30.0,
                                                f'a profile {args.passive_age:g} s after the probe')
                    finally:
                        load.stop()
                quiet = time.time()
                sample = Sample(
                    set_rtt_ms=rtt, set_rate_mbit=rate, rep=rep, rtt_ms=1e3 * p.rtt, rtt_spread_ms=1e3 * p.rtt_spread,
                    probe_ok=int(answer.success), a_bw_mbit=answer.profile.a_bw / 1e6 if answer.success else math.nan,
                    probe_s=probe_s, probe_iperf_bytes=int(answer.profile.probe_bytes - before_bytes),
                    probe_link_up_bytes=after_link[0] - before_link[0],
                    probe_link_down_bytes=after_link[1] - before_link[1],
                    load_mbit=args.load_fraction * rate if passive else math.nan,
                    passive_mbit=passive.a_bw / 1e6 if passive else math.nan,
                    passive_age_s=passive.a_bw_age if passive else math.nan,
                    passive_method=A_BW_METHOD_WORD[passive.a_bw_method] if passive else '',
                    usage_mbit=passive.c_bw / 1e6 if passive else math.nan)
                log.row(**vars(sample))
                setting = f"{rtt:5g} ms {rate:4g} Mbit/s" if rate else f"{rtt:5g} ms unshaped"
                probe = (f'A_bw {sample.a_bw_mbit:7.2f} Mbit/s, {sample.probe_link_bytes / 1e6:6.2f} MB, '
                         f'{probe_s:5.2f} s' if answer.success else f'probe FAILED: {answer.message}')
                passive_text = (f', passive {sample.passive_mbit:6.2f} Mbit/s at {sample.passive_age_s:4.1f} s '
                                f'({sample.passive_method}, usage {sample.usage_mbit:5.2f} Mbit/s)' if passive else '')
                progress(f'  {setting} rep {rep}: RTT {sample.rtt_ms:7.2f} ms, {probe}{passive_text}')
    finally:
        log.close()
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description='bench_profile: the measuring node (see the module docstring)')
    ap.add_argument('--sink', action='store_true', help='only subscribe the background load (on the cloud)')
    ap.add_argument('--testbed-config')
    ap.add_argument('--testbed-name')
    ap.add_argument('--cells', help='RTT_MS:RATE_MBIT,... (rate 0 = unshaped)')
    ap.add_argument('--reps', type=int)
    ap.add_argument('--out', help='TSV file')
    ap.add_argument('--load-fraction', type=float)
    ap.add_argument('--load-hz', type=float)
    ap.add_argument('--passive-age', type=float)
    import rospy
    args = ap.parse_args(rospy.myargv(argv if argv is not None else sys.argv)[1:])
    if args.sink:
        return run_sink()
    missing = [k for k, v in vars(args).items() if v is None]
    if missing:
        ap.error(f'missing: {", ".join("--" + k.replace("_", "-") for k in missing)}')
    return run(args)


if __name__ == '__main__':
    sys.exit(main())
