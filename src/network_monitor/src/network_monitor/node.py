"""The ``network_monitor`` node: network profile towards one peer host (see the package README).

ROS I/O and threads only; the measurements are in :mod:`network_monitor.core`. Every loop runs on the
monotonic clock (not ROS time, which may be simulated), and nothing waits on the peer without a timeout.
"""
from __future__ import annotations

import ipaddress
import os
import socket
import subprocess
import threading
import time
from typing import Callable, Optional

import netifaces
import psutil
import rospy
from std_msgs.msg import Header

from cnr_msgs.msg import LinkQuality, NetworkProfile
from cnr_msgs.srv import ProfileNow, ProfileNowResponse
from cnr_params import exit_on_config_error
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from network_monitor.codes import A_BW_METHOD
from network_monitor.core import config as monitor_config
from network_monitor.core.echo import EchoStats, LinkSample, link_state
from network_monitor.core.estimate import BandwidthEstimator, r_bw
from network_monitor.core.iface import choose_interface, netifaces_table
from network_monitor.core.probe import ProbeResult, run_probe
from network_monitor.core.rate import RateSampler, psutil_reader
from network_monitor.train_probe import TrainResponder, run_train_probe


def resolve_ipv4(address: str) -> str:
    """``address`` if it is an IPv4 address, else its first IPv4 address by name ('' if none)."""
    try:
        return str(ipaddress.IPv4Address(address))
    except ValueError:
        pass
    try:
        return socket.getaddrinfo(address, None, socket.AF_INET)[0][4][0]
    except (OSError, IndexError):
        return ''


class Monitor:
    def __init__(self, cfg: monitor_config.MonitorConfig) -> None:
        self.cfg = cfg
        self.lock = threading.Lock()
        self.probe_lock = threading.Lock()
        self.stop = threading.Event()
        self.session = f'{os.getpid()}-{int(time.time() * 1000) % 1000000}'
        self.frame_id = f'{cfg.name}:{self.session}'
        self.echo = EchoStats(cfg.window, cfg.reply_timeout)
        self.sampler = RateSampler(cfg.sample_period, max(cfg.c_bw_span, cfg.passive.window))
        self.estimator = BandwidthEstimator(cfg.passive)
        self.read_counters = psutil_reader(psutil)
        self.bridge: Optional[LinkSample] = None
        self.probing = False
        self.probe_bytes = 0
        self.last_probe: Optional[ProbeResult] = None
        address = resolve_ipv4(cfg.peer_address)
        self.train_address = address or cfg.peer_address     # the train's target: resolved once, here
        table, default = netifaces_table(netifaces)
        choice = choose_interface(address, table, default, cfg.interface)
        self.interface = choice.interface
        rospy.loginfo(f'network_monitor {cfg.name}: peer {cfg.peer} at {cfg.peer_address}, interface '
                      f"'{self.interface}' ({choice.reason})")
        self.server: Optional[subprocess.Popen] = None
        if cfg.iperf3_server:
            self.start_server()
        self.responder: Optional[TrainResponder] = None
        if cfg.train_server:
            self.start_responder()
        self.ping_pub = rospy.Publisher(cfg.topic(cfg.name, 'ping'), Header, queue_size=10)
        self.echo_pub = rospy.Publisher(cfg.topic(cfg.peer, 'pong'), Header, queue_size=10)
        self.profile_pub = rospy.Publisher(cfg.topic(cfg.name, 'network_profile'), NetworkProfile, queue_size=5)
        rospy.Subscriber(cfg.topic(cfg.name, 'pong'), Header, self.on_pong, queue_size=50)
        rospy.Subscriber(cfg.topic(cfg.peer, 'ping'), Header, self.on_peer_ping, queue_size=50)
        rospy.Subscriber(cfg.link_quality_topic, LinkQuality, self.on_link_quality, queue_size=10)
        rospy.Service('~profile_now', ProfileNow, self.on_profile_now)

    # ---------------------------------------------------------------- iperf3 server
    def start_server(self) -> None:
        argv = [self.cfg.iperf3_executable, '-s', '-p', str(self.cfg.iperf3_server_port)]
        try:
            self.server = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL, start_new_session=True)
        except OSError as exc:
            rospy.logerr(f'network_monitor: cannot start {" ".join(argv)}: {exc.strerror or exc}')

    def stop_server(self) -> None:
        if self.server is None or self.server.poll() is not None:
            return
        self.server.terminate()
        try:
            self.server.wait(2.0)
        except subprocess.TimeoutExpired:
            self.server.kill()
            self.server.wait(2.0)

    # ---------------------------------------------------------------- train responder
    def start_responder(self) -> None:
        try:
            self.responder = TrainResponder.start(self.cfg.train_server_port, self.cfg.train.gap,
                                                  on_error=rospy.logwarn)
        except OSError as exc:
            rospy.logerr(f'network_monitor: cannot answer packet trains on UDP port {self.cfg.train_server_port}: '
                         f'{exc.strerror or exc}')

    def stop_responder(self) -> None:
        if self.responder is not None:
            self.responder.close()

    # ---------------------------------------------------------------- echo
    def on_pong(self, msg: Header) -> None:
        if msg.frame_id != self.frame_id:
            return
        with self.lock:
            self.echo.reply(msg.seq, time.monotonic())

    @quiet_at_shutdown
    def on_peer_ping(self, msg: Header) -> None:
        self.echo_pub.publish(msg)

    def on_link_quality(self, msg: LinkQuality) -> None:
        if msg.peer != self.cfg.peer:
            return
        sample = LinkSample(time.monotonic(), msg.alive, msg.rtt, msg.rtt_stddev, msg.loss)
        with self.lock:
            self.bridge = sample

    def send_ping(self) -> None:
        with self.lock:
            seq = self.echo.send(time.monotonic())
        self.ping_pub.publish(Header(seq=seq, stamp=rospy.Time.from_sec(time.time()), frame_id=self.frame_id))

    # ---------------------------------------------------------------- C_bw
    def sample(self) -> None:
        if not self.interface:
            return
        with self.lock:
            if self.probing:
                self.sampler.gap()
                return
        counters = self.read_counters(self.interface)
        with self.lock:
            if not self.probing:
                self.sampler.add(time.monotonic(), counters)

    # ---------------------------------------------------------------- A_bw
    def probe(self) -> Optional[ProbeResult]:
        """One probe unless another is running (then None after waiting for it at most probe_timeout + 1 s)."""
        if not self.probe_lock.acquire(timeout=self.cfg.probe.timeout + 1.0):
            return None
        try:
            with self.lock:
                self.probing = True
                self.sampler.gap()
            if self.cfg.probe_method == 'train':
                result = run_train_probe(self.train_address, self.cfg.train_port, self.cfg.train)
            else:
                result = run_probe(self.cfg.peer_address, self.cfg.probe_port, self.cfg.probe,
                                   self.cfg.iperf3_executable)
            with self.lock:
                self.probing = False
                self.sampler.gap()
                self.probe_bytes += result.bytes_sent
                self.last_probe = result
                if result.ok:
                    self.estimator.probed(time.monotonic(), result.bits_per_second)
            if not result.ok:
                rospy.logwarn(f'network_monitor: probe of {self.cfg.peer} failed: {result.error}')
            return result
        finally:
            self.probe_lock.release()

    def wait_for_usage(self, since: float) -> None:
        """Wait until a C_bw window ends after ``since`` (the probe's end: the windows during a probe are
        dropped, and a probe longer than c_bw_span would leave C_bw unknown), at most 3 sample periods."""
        deadline = since + 3.0 * self.cfg.sample_period
        while time.monotonic() < deadline:
            with self.lock:
                if self.sampler.last_end() > since:
                    return
            if self.stop.wait(self.cfg.sample_period / 4.0):
                return

    # ---------------------------------------------------------------- profile
    def link_now(self):
        now = time.monotonic()
        with self.lock:
            return link_state(self.echo.summary(now), now, self.cfg.alive_timeout, self.bridge,
                              self.cfg.link_quality_timeout)

    def profile(self, link=None) -> NetworkProfile:
        """The profile now; ``link`` (RTT, spread, loss, alive) taken earlier instead of now's window."""
        now = time.monotonic()
        cfg = self.cfg
        link = link or self.link_now()
        with self.lock:
            c_bw = self.sampler.mean(now, cfg.c_bw_span)
            peak = self.sampler.peak(now, self.estimator.usage_span(now))
            a_bw, age, method = self.estimator.estimate(now, peak)
            probe_bytes = self.probe_bytes
        msg = NetworkProfile(peer=cfg.peer, alive=link.alive, rtt=link.rtt, rtt_spread=link.rtt_spread,
                             loss=link.loss, c_bw=c_bw, a_bw=a_bw, a_bw_age=age, a_bw_method=A_BW_METHOD[method],
                             r_bw=r_bw(a_bw, c_bw, cfg.c_bw_floor), interface=self.interface,
                             probe_bytes=probe_bytes)
        msg.header.stamp = rospy.Time.now()
        return msg

    def on_profile_now(self, req) -> ProfileNowResponse:
        if not req.probe:
            return ProfileNowResponse(profile=self.profile(), success=True, message='no probe requested')
        # RTT, spread and loss from the echo window before the probe: during it the probe's own queue on a slow
        # link is what the pings would measure (seen: 261 ms on a 125 ms link at 15 Mbit/s)
        link = self.link_now()
        result = self.probe()
        self.wait_for_usage(time.monotonic())
        if result is None:
            return ProfileNowResponse(profile=self.profile(link), success=False, message='another probe is running')
        if not result.ok:
            return ProfileNowResponse(profile=self.profile(link), success=False, message=result.error)
        return ProfileNowResponse(profile=self.profile(link), success=True,
                                  message=f'probe: {result.bits_per_second:.0f} bit/s, {result.bytes_sent} bytes')

    # ---------------------------------------------------------------- loops
    def every(self, period: float, action: Callable[[], None], first: float = 0.0) -> threading.Thread:
        def loop() -> None:
            deadline = time.monotonic() + first
            while not self.stop.wait(max(0.0, deadline - time.monotonic())):
                try:
                    action()
                except rospy.ROSException:
                    if rospy.is_shutdown():
                        return
                    raise
                deadline = max(deadline + period, time.monotonic())
        thread = threading.Thread(target=loop, daemon=True)
        thread.start()
        return thread

    def run(self) -> None:
        cfg = self.cfg
        self.every(cfg.sample_period, self.sample)
        self.every(1.0 / cfg.echo_rate, self.send_ping)
        self.every(1.0 / cfg.publish_rate, lambda: self.profile_pub.publish(self.profile()))
        if cfg.probe_interval > 0:
            self.every(cfg.probe_interval, self.probe)
        try:
            while not rospy.is_shutdown() and not self.stop.wait(0.2):
                if self.server is not None and self.server.poll() is not None:
                    rospy.logerr(f'network_monitor: iperf3 server exited with {self.server.returncode} '
                                 f'(port {cfg.iperf3_server_port} in use?)')
                    self.server = None
        finally:
            self.stop.set()
            self.stop_server()
            self.stop_responder()


@exit_on_config_error
def main() -> None:
    init_node('network_monitor')
    cfg = monitor_config.from_section(private_section())
    monitor = Monitor(cfg)
    rospy.on_shutdown(monitor.stop.set)
    rospy.on_shutdown(monitor.stop_server)
    rospy.on_shutdown(monitor.stop_responder)
    monitor.run()
