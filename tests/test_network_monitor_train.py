"""network_monitor's packet-train A_bw probe: the dispersion estimator on arrivals made by the testbed's own link
model (token bucket, no burst, delay, loss), the wire format, the UDP sender and responder over localhost (no
master), and the configuration of the new parameters."""
import math
import random
import socket
import time

import pytest

from cnr_params import ConfigError, Section, load_yaml
from cnr_testbed.core.link import Conditions, LinkDirection
from network_monitor.core import config as monitor_config
from network_monitor.core.train import (IP_UDP_OVERHEAD, MAX_PACKETS, TRAIN_HEADER, TrainSettings, estimate_train,
                                        minimum_received, parse_summary, parse_train_packet, summary_datagram,
                                        train_packet)
from network_monitor.train_probe import TrainResponder, run_train_probe

COUNT, SIZE = 60, 1472


def through_link(rate, delay=0.0, loss=0.0, count=COUNT, size=SIZE, send_gap=5e-6, first_pause=0.0, seed=1):
    """(seq, arrival [ns]) of a back-to-back train through one emulated direction (rate Mbit/s, delay ms): the
    link carries the IP packet, payload plus IPv4/UDP headers. ``first_pause``: s the sender stalls after its
    first packet (route lookup, ARP)."""
    link = LinkDirection(Conditions(delay=delay, jitter=0.0, loss=loss, rate=rate, queue=1000, outage=False,
                                    reorder=False), random.Random(seed))
    t = 0.0
    for seq in range(count):
        link.offer(train_packet(7, seq, count, 0, size) + bytes(IP_UDP_OVERHEAD), t)
        t += send_gap + (first_pause if seq == 0 else 0.0)
    arrivals = []
    while link.next_due() is not None:
        now = link.next_due()
        arrivals += [(parse_train_packet(p).seq, 10 ** 12 + round(now * 1e9)) for p in link.due(now)]
    return arrivals


def via_summary(arrivals, count=COUNT):
    """The arrivals as the sender gets them back: through the responder's summary datagram."""
    data = summary_datagram(7, count, arrivals)
    assert len(data) <= 1472
    summary = parse_summary(data)
    assert (summary.train_id, summary.count) == (7, count)
    return summary.arrivals


# ---------------------------------------------------------------- estimator
@pytest.mark.parametrize('rate', [0.5, 1.0, 2.0, 5.0, 10.0, 25.0, 50.0])
@pytest.mark.parametrize('delay,loss', [(0.0, 0.0), (75.0, 0.02)])
def test_the_dispersion_rate_is_the_links_rate(rate, delay, loss):
    arrivals = via_summary(through_link(rate, delay, loss, seed=int(rate * 10)))
    est = estimate_train(arrivals, COUNT, SIZE)
    assert est.ok, est.error
    assert est.bits_per_second == pytest.approx(rate * 1e6, rel=0.05)
    assert est.capacity == pytest.approx(rate * 1e6, rel=0.05)
    assert est.received == len(arrivals) and est.loss == pytest.approx(1 - len(arrivals) / COUNT)
    used = sorted(seq for seq, _ in arrivals)[1:]
    assert est.seconds == pytest.approx((used[-1] - used[0]) * (SIZE + IP_UDP_OVERHEAD) * 8 / (rate * 1e6), rel=0.01)
    result = est.result(COUNT * SIZE)
    assert (result.ok, result.bytes_sent, result.bits_per_second) == (True, 88320, est.bits_per_second)


def test_random_loss_is_reported_and_does_not_bias_the_rate():
    arrivals = through_link(10.0, 20.0, 0.2, seed=3)
    est = estimate_train(arrivals, COUNT, SIZE)
    assert est.ok and 0.1 < est.loss < 0.3
    assert est.received == len(arrivals) < COUNT
    assert est.bits_per_second == pytest.approx(10e6, rel=0.001)   # lost packets took their turn on the link
    assert est.capacity == pytest.approx(10e6, rel=0.001)          # back-to-back pairs see the rate too


def test_the_first_packets_wait_is_left_out():
    # the sender stalls 3 ms after its first packet: at 50 Mbit/s the whole train takes 14 ms
    arrivals = through_link(50.0, 10.0, first_pause=3e-3)
    est = estimate_train(arrivals, COUNT, SIZE)
    assert est.bits_per_second == pytest.approx(50e6, rel=0.01)
    naive = (SIZE + IP_UDP_OVERHEAD) * 8 * (COUNT - 1) / ((arrivals[-1][1] - arrivals[0][1]) / 1e9)
    assert naive < 0.85 * 50e6


def test_arrival_order_repeats_and_foreign_seqs_do_not_matter():
    arrivals = through_link(5.0, 5.0)
    shuffled = list(reversed(arrivals)) + arrivals[:5] + [(COUNT + 3, 0), (10 ** 6, 5)]
    assert estimate_train(shuffled, COUNT, SIZE) == estimate_train(arrivals, COUNT, SIZE)


def test_too_few_packets_back_is_a_failed_probe():
    assert minimum_received(60) == 30 and minimum_received(3) == 3 and minimum_received(5) == 3
    arrivals = through_link(5.0)[:29]
    est = estimate_train(arrivals, COUNT, SIZE)
    assert not est.ok and math.isnan(est.bits_per_second)
    assert est.error == 'train: only 29 of 60 packets came back (at least 30 needed)'
    assert not estimate_train([], COUNT, SIZE).ok
    heavy = estimate_train(through_link(5.0, loss=0.7, seed=2), COUNT, SIZE)
    assert not heavy.ok and 'packets came back' in heavy.error
    result = heavy.result(88320)
    assert (result.ok, result.bytes_sent) == (False, 88320) and math.isnan(result.bits_per_second)


def test_no_dispersion_is_a_failed_probe():
    est = estimate_train([(seq, 1000) for seq in range(COUNT)], COUNT, SIZE)
    assert not est.ok and 'no dispersion' in est.error


# ---------------------------------------------------------------- wire format
def test_train_packets_are_padded_and_parsed():
    data = train_packet(0xDEADBEEF, 59, 60, 1234567890123, SIZE)
    assert len(data) == SIZE
    p = parse_train_packet(data)
    assert (p.train_id, p.seq, p.count, p.sent_ns) == (0xDEADBEEF, 59, 60, 1234567890123)
    assert len(train_packet(1, 0, 3, 0, 10)) == TRAIN_HEADER.size       # never shorter than its header
    assert parse_train_packet(b'CNRT') is None
    assert parse_train_packet(b'XXXX' + data[4:]) is None
    assert parse_train_packet(train_packet(1, 3, 3, 0, SIZE)) is None    # seq beyond count
    assert TrainSettings(60, 1472, 0.5, 8.0).train_bytes == 88320       # 88 KB per probe


def test_summaries_round_trip_and_fit_one_datagram():
    arrivals = [(seq, 5_000 + 240_000 * seq) for seq in range(0, MAX_PACKETS + 10, 2)]
    data = summary_datagram(9, MAX_PACKETS + 10, arrivals)
    summary = parse_summary(data)
    assert len(data) <= 1472 and summary.train_id == 9
    assert summary.arrivals[0] == (0, 0) and summary.arrivals[1] == (2, 480_000)
    full = summary_datagram(9, MAX_PACKETS, [(seq, seq) for seq in range(MAX_PACKETS)])
    assert len(full) <= 1472 and len(parse_summary(full).arrivals) == MAX_PACKETS
    assert parse_summary(data[:-3]) is None and parse_summary(b'CNRT' + data[4:]) is None
    assert parse_summary(b'') is None


# ---------------------------------------------------------------- over localhost UDP (no master)
@pytest.fixture
def responder():
    r = TrainResponder.start(0, 0.3, '127.0.0.1')
    yield r
    r.close()


def test_a_train_over_localhost_measures_a_plausible_rate(responder):
    settings = TrainSettings(COUNT, SIZE, 0.3, 3.0)
    result = run_train_probe('127.0.0.1', responder.port, settings)
    assert result.ok, result.error
    assert result.bytes_sent == 88320
    assert result.bits_per_second > 20e6 and 0 < result.seconds < 1.0
    assert responder.answered == 1


def test_an_incomplete_train_is_answered_after_the_gap(responder):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect(('127.0.0.1', responder.port))
        sock.settimeout(3.0)
        start = time.monotonic()
        for seq in [0, 1, 2, 4, 5, 7]:                     # of 10; 3, 6, 8, 9 lost
            sock.send(train_packet(42, seq, 10, time.time_ns(), 200))
        sock.send(b'not a train packet')
        summary = parse_summary(sock.recv(65535))
        waited = time.monotonic() - start
    assert summary.train_id == 42 and summary.count == 10
    assert sorted(seq for seq, _ in summary.arrivals) == [0, 1, 2, 4, 5, 7]
    assert summary.arrivals[0][1] == 0 and all(t >= 0 for _, t in summary.arrivals)
    assert 0.3 <= waited < 2.0


def test_a_silent_peer_fails_within_the_timeout():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(('127.0.0.1', 0))
        start = time.monotonic()
        result = run_train_probe('127.0.0.1', silent.getsockname()[1], TrainSettings(COUNT, SIZE, 0.1, 0.5))
        waited = time.monotonic() - start
    assert not result.ok and math.isnan(result.bits_per_second)
    assert 'no reply within 0.5 s' in result.error and result.bytes_sent == 88320
    assert 0.5 <= waited < 1.5


def test_nobody_listening_or_no_such_host_fails_without_raising():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]                          # free again once closed
    result = run_train_probe('127.0.0.1', port, TrainSettings(COUNT, SIZE, 0.1, 2.0))
    assert not result.ok and f'127.0.0.1:{port}' in result.error
    bad = run_train_probe('no-such-host.invalid', 5202, TrainSettings(COUNT, SIZE, 0.1, 2.0))
    assert not bad.ok and bad.bytes_sent == 0 and bad.error.startswith('train to no-such-host.invalid:5202: ')


# ---------------------------------------------------------------- configuration
def test_the_train_parameters_are_validated(workspace):
    path = f'{workspace}/config/network_monitor.yaml'
    cfg = monitor_config.from_section(Section.from_file(path))
    assert cfg.probe_method == 'train' and not cfg.train_server          # the responder runs on the peer
    assert (cfg.train.packets, cfg.train.packet_bytes, cfg.train.gap, cfg.train.timeout) == (60, 1472, 0.5, 8.0)
    assert (cfg.train_port, cfg.train_server_port) == (5202, 5202)
    for key in ('probe_method', 'train_packets', 'train_packet_bytes', 'train_gap', 'train_port', 'train_server',
                'train_server_port'):
        data = load_yaml(path)
        del data[key]
        with pytest.raises(ConfigError, match=rf'^x: {key}: missing$'):
            monitor_config.from_section(Section(data, 'x'))
    with pytest.raises(ConfigError, match=r"probe_method: unknown value 'netperf'"):
        monitor_config.from_section(Section(dict(load_yaml(path), probe_method='netperf'), 'x'))
    with pytest.raises(ConfigError, match=r'train_packets: must be <= 121'):
        monitor_config.from_section(Section(dict(load_yaml(path), train_packets=500), 'x'))
    with pytest.raises(ConfigError, match=r'train_gap: must be < probe_timeout \(8 s\)'):
        monitor_config.from_section(Section(dict(load_yaml(path), train_gap=8.0), 'x'))
    train = monitor_config.from_section(Section(dict(load_yaml(path), probe_method='train'), 'x'))
    assert train.probe_method == 'train'
