"""network_monitor core without ROS: echo RTT/loss, counter windows, interface choice, iperf3 results,
the passive A_bw estimate and R_bw (thesis Eq. 4-1). Every time is an argument, so these are exact."""
import json
import math
import subprocess

import pytest

from cnr_params import ConfigError, Section, load_yaml
from network_monitor.core import config as monitor_config
from network_monitor.core.echo import EchoStats, LinkSample, link_state
from network_monitor.core.estimate import BandwidthEstimator, PassiveSettings, r_bw
from network_monitor.core.iface import Choice, choose_interface, netifaces_table
from network_monitor.core.probe import ProbeSettings, iperf3_command, parse_iperf3_json, run_probe
from network_monitor.core.rate import RateSampler, sysfs_reader

TABLE = {'lo': [('127.0.0.1', '255.0.0.0')],
         'eth0': [('192.168.1.10', '255.255.255.0')],
         'veth0': [('10.77.0.1', '255.255.255.0')],
         'wide': [('10.0.0.1', '255.0.0.0')]}


# ---------------------------------------------------------------- echo
def test_rtt_median_spread_and_loss_over_the_window():
    e = EchoStats(window=10.0, reply_timeout=1.0)
    seqs = [e.send(t) for t in (0.0, 0.2, 0.4, 0.6, 0.8)]
    for seq, rtt in zip(seqs[:4], (0.010, 0.020, 0.030, 0.040)):
        assert e.reply(seq, (seq - 1) * 0.2 + rtt) == pytest.approx(rtt)
    s = e.summary(1.5)                       # the 5th ping (sent 0.8) is still undecided
    assert (s.sent, s.answered, s.decided) == (5, 4, 4)
    assert s.rtt == pytest.approx(0.025) and s.rtt_spread == pytest.approx(0.015)
    assert s.loss == 0.0
    s = e.summary(1.9)                       # now timed out
    assert s.decided == 5 and s.loss == pytest.approx(0.2)


def test_late_duplicate_and_unknown_replies_are_ignored():
    e = EchoStats(window=10.0, reply_timeout=1.0)
    a, b = e.send(0.0), e.send(0.0)
    assert e.reply(a, 1.5) is None           # too late: stays lost
    assert e.reply(b, 0.1) == pytest.approx(0.1)
    assert e.reply(b, 0.2) is None           # duplicate
    assert e.reply(99, 0.3) is None          # never sent
    s = e.summary(2.0)
    assert s.answered == 1 and s.loss == pytest.approx(0.5) and s.rtt == pytest.approx(0.1)


def test_window_forgets_old_pings_and_no_data_is_nan():
    e = EchoStats(window=2.0, reply_timeout=0.5)
    e.reply(e.send(0.0), 0.05)
    assert e.summary(1.0).answered == 1
    s = e.summary(5.0)
    assert s.sent == 0 and not s.has_data and math.isnan(s.rtt) and math.isnan(s.loss)


def test_link_state_prefers_the_echo_then_a_fresh_bridge_sample():
    e = EchoStats(window=5.0, reply_timeout=1.0)
    bridge = LinkSample(received=10.0, alive=True, rtt=0.05, rtt_stddev=0.01, loss=0.1)
    ls = link_state(e.summary(10.5), 10.5, 2.0, bridge, 2.0)
    assert (ls.source, ls.alive, ls.rtt, ls.rtt_spread, ls.loss) == ('link_quality', True, 0.05, 0.01, 0.1)
    ls = link_state(e.summary(13.0), 13.0, 2.0, bridge, 2.0)
    assert ls.source == 'none' and not ls.alive and math.isnan(ls.rtt)
    e.reply(e.send(13.0), 13.02)
    ls = link_state(e.summary(13.1), 13.1, 2.0, bridge, 100.0)
    assert ls.source == 'echo' and ls.alive and ls.rtt == pytest.approx(0.02)
    ls = link_state(e.summary(15.5), 15.5, 2.0, None, 2.0)
    assert ls.source == 'echo' and not ls.alive   # last pong 2.48 s ago


# ---------------------------------------------------------------- C_bw
def test_rate_windows_in_bits_per_second_with_gaps_and_resets():
    r = RateSampler(min_window=0.1, history=10.0)
    assert r.last_end() == -math.inf
    assert r.add(0.0, (1000, 0)) is None     # baseline
    assert r.add(0.05, (1100, 0)) is None    # too short (< 0.9 x 0.1 s): merged into the next window
    assert r.add(0.1, (1000 + 500, 750)) == pytest.approx(8 * 1250 / 0.1)
    assert r.add(0.2, (1000, 0)) is None     # counter went back: new baseline
    assert r.add(0.3, (1125, 0)) == pytest.approx(8 * 125 / 0.1)
    r.gap()
    assert r.add(0.4, (10 ** 9, 0)) is None  # probe traffic in the gap is not counted
    assert r.add(0.5, None) is None          # interface gone
    assert r.add(0.6, (10 ** 9, 0)) is None
    assert r.add(0.7, (10 ** 9 + 250, 0)) == pytest.approx(20000.0)
    assert r.last() == pytest.approx(20000.0) and r.last_end() == 0.7
    assert r.mean(0.7, 0.45) == pytest.approx((10000.0 + 20000.0) / 2)
    assert r.peak(0.7, 1.0) == pytest.approx(100000.0)
    assert math.isnan(r.mean(100.0, 1.0))


def test_sysfs_reader(tmp_path):
    stats = tmp_path / 'eth9' / 'statistics'
    stats.mkdir(parents=True)
    (stats / 'rx_bytes').write_text('12\n')
    (stats / 'tx_bytes').write_text('34\n')
    read = sysfs_reader(str(tmp_path))
    assert read('eth9') == (12, 34) and read('nope') is None


# ---------------------------------------------------------------- interface
@pytest.mark.parametrize('peer,configured,expected', [
    ('127.0.0.1', '', ('lo', 'loopback')),
    ('192.168.1.10', '', ('lo', 'local address')),
    ('192.168.1.77', '', ('eth0', 'subnet')),
    ('10.77.0.2', '', ('veth0', 'subnet')),      # longest prefix beats the /8
    ('10.9.9.9', '', ('wide', 'subnet')),
    ('8.8.8.8', '', ('eth0', 'default gateway')),
    ('not-an-ip', '', ('eth0', 'default gateway')),
    ('10.77.0.2', 'wlan0', ('wlan0', 'configured')),
])
def test_interface_choice(peer, configured, expected):
    c = choose_interface(peer, TABLE, 'eth0', configured)
    assert (c.interface, c.reason) == expected


def test_a_point_to_point_device_whose_remote_end_is_the_peer():
    # the testbed's TUN device: 10.77.0.1 peer 10.77.0.2/32 (no subnet contains the peer)
    table = {'lo': [('127.0.0.1', '255.0.0.0')], 'bp-r': [('10.77.0.1', '255.255.255.255', '10.77.0.2')]}
    assert choose_interface('10.77.0.2', table, None) == Choice('bp-r', 'point-to-point')
    assert choose_interface('10.77.0.1', table, None) == Choice('lo', 'local address')
    assert choose_interface('10.77.0.3', table, None).interface == ''


def test_no_interface_fits():
    assert choose_interface('8.8.8.8', {'eth0': [('192.168.1.10', '255.255.255.0')]}, None).interface == ''


def test_netifaces_table_from_a_fake_module():
    class Fake:
        AF_INET = 2

        @staticmethod
        def interfaces():
            return ['lo', 'eth0', 'can0', 'tun0']

        @staticmethod
        def ifaddresses(name):
            return {'lo': {2: [{'addr': '127.0.0.1', 'netmask': '255.0.0.0'}]},
                    'eth0': {2: [{'addr': '192.168.1.10', 'netmask': '255.255.255.0'}], 10: [{'addr': 'fe80::1'}]},
                    'can0': {},
                    'tun0': {2: [{'addr': '10.77.0.1', 'netmask': '255.255.255.255', 'peer': '10.77.0.2'}]}}[name]

        @staticmethod
        def gateways():
            return {'default': {2: ('192.168.1.1', 'eth0')}}

    table, default = netifaces_table(Fake)
    assert table == {'lo': [('127.0.0.1', '255.0.0.0')], 'eth0': [('192.168.1.10', '255.255.255.0')], 'can0': [],
                     'tun0': [('10.77.0.1', '255.255.255.255', '10.77.0.2')]}
    assert default == 'eth0'


def test_real_netifaces_finds_loopback():
    netifaces = pytest.importorskip('netifaces')
    table, _ = netifaces_table(netifaces)
    assert choose_interface('127.0.0.1', table, None).interface == 'lo'


# ---------------------------------------------------------------- iperf3
GOOD = {'start': {}, 'intervals': [],
        'end': {'sum_sent': {'bytes': 1000000, 'seconds': 0.01, 'bits_per_second': 8.1e8},
                'sum_received': {'bytes': 1000000, 'seconds': 0.0102, 'bits_per_second': 7.9e8}}}


def test_iperf3_success_uses_the_received_rate():
    r = parse_iperf3_json(json.dumps(GOOD))
    assert r.ok and r.bits_per_second == 7.9e8 and r.bytes_sent == 1000000 and r.seconds == 0.0102


def test_iperf3_bytes_include_the_omitted_seconds():
    data = dict(GOOD, intervals=[{'sum': {'bytes': 3000000, 'omitted': True}},
                                 {'sum': {'bytes': 1000000, 'omitted': False}}])
    r = parse_iperf3_json(json.dumps(data))
    assert r.ok and r.bytes_sent == 4000000 and r.bits_per_second == 7.9e8


def test_the_probe_is_time_bounded_with_omitted_slow_start_and_paced_to_its_byte_cap():
    settings = ProbeSettings(seconds=2, omit=2, max_bytes=50000000, timeout=8.0)
    argv = iperf3_command('iperf3', '10.0.0.2', 5201, settings)
    assert argv[argv.index('-t') + 1] == '2' and argv[argv.index('-O') + 1] == '2'
    assert argv[argv.index('-b') + 1] == '100000000' and settings.cap == 100000000   # 50 MB over 4 s
    assert '-n' not in argv and '-J' in argv and argv[argv.index('--connect-timeout') + 1] == '4000'


@pytest.mark.parametrize('text,fragment', [
    (json.dumps({'start': {}, 'intervals': [], 'end': {},
                 'error': 'unable to connect to server: Connection refused'}), 'Connection refused'),
    (json.dumps({'error': 'the server is busy running a test. try again later'}), 'busy'),
    (json.dumps({'end': {'sum_received': {'bits_per_second': 0}}}), 'no received rate'),
    ('iperf3: error - unable to connect', 'not JSON'),
    ('', 'not JSON'),
    ('[1, 2]', 'not a JSON object'),
])
def test_iperf3_errors_become_results(text, fragment):
    r = parse_iperf3_json(text)
    assert not r.ok and fragment in r.error and math.isnan(r.bits_per_second)


def test_run_probe_never_raises():
    settings = ProbeSettings(seconds=1, omit=1, max_bytes=1000, timeout=4.0)

    def timeout(argv, t):
        raise subprocess.TimeoutExpired(argv, t)

    def good(argv, t):
        assert argv == iperf3_command('iperf3', '10.0.0.2', 5201, settings) and t == 4.0
        return subprocess.CompletedProcess(argv, 0, json.dumps(GOOD), '')

    def crash(argv, t):
        return subprocess.CompletedProcess(argv, 1, '', 'iperf3: error - bad\n')

    assert 'within 4 s' in run_probe('10.0.0.2', 5201, settings, 'iperf3', runner=timeout).error
    assert run_probe('10.0.0.2', 5201, settings, 'iperf3', runner=good).ok
    assert run_probe('10.0.0.2', 5201, settings, 'iperf3', runner=crash).error == \
        'iperf3 exited with 1: iperf3: error - bad'
    r = run_probe('127.0.0.1', 5201, settings, '/nonexistent/iperf3')
    assert not r.ok and 'cannot run' in r.error


# ---------------------------------------------------------------- A_bw and R_bw
SETTINGS = PassiveSettings(fresh=2.0, window=10.0, half_life=30.0, floor_fraction=0.25)


def test_no_probe_means_no_estimate():
    a, age, method = BandwidthEstimator(SETTINGS).estimate(5.0, 1e6)
    assert math.isnan(a) and math.isnan(age) and method == 'none'


def test_passive_estimate_decays_towards_proven_usage_and_is_raised_by_it():
    b = BandwidthEstimator(SETTINGS)
    b.probed(100.0, 8e6)
    assert b.estimate(101.0, 1e6)[2] == 'probe'
    a, age, method = b.estimate(130.0, 4e6)             # one half-life: halfway from 8 to 4 Mbit/s
    assert (a, age, method) == (pytest.approx(6e6), 30.0, 'passive')
    assert b.estimate(10000.0, 4e6)[0] == pytest.approx(4e6)
    assert b.estimate(10000.0, math.nan)[0] == pytest.approx(2e6)   # idle link: the floor fraction
    assert b.estimate(130.0, 9e6)[0] == 9e6                         # usage above the estimate raises it
    b.probed(200.0, 5e6)
    assert b.estimate(200.0, 0.0) == (5e6, 0.0, 'probe')


def test_only_usage_since_the_probe_counts_for_the_passive_estimate():
    b = BandwidthEstimator(SETTINGS)
    assert b.usage_span(50.0) == 10.0                   # no probe yet: the whole passive window
    b.probed(100.0, 1e6)
    assert b.usage_span(100.0) == 0.0 and b.usage_span(104.0) == 4.0 and b.usage_span(130.0) == 10.0


def test_r_bw_is_eq_4_1_with_a_floored_c_bw():
    assert r_bw(8e6, 2e6, 1000.0) == 4.0
    assert r_bw(8e6, 0.0, 1000.0) == 8000.0             # idle link: finite, A_bw / floor
    assert math.isnan(r_bw(math.nan, 2e6, 1000.0)) and math.isnan(r_bw(8e6, math.nan, 1000.0))


# ---------------------------------------------------------------- config
def test_the_shipped_config_is_valid_and_a_missing_parameter_is_named(workspace):
    path = f'{workspace}/config/network_monitor.yaml'
    cfg = monitor_config.from_section(Section.from_file(path))
    assert cfg.topic(cfg.name, 'ping') == 'network_monitor/robot/ping'
    data = load_yaml(path)
    del data['probe_bytes']
    with pytest.raises(ConfigError, match=r'^x: probe_bytes: missing$'):
        monitor_config.from_section(Section(data, 'x'))
    with pytest.raises(ConfigError, match='peer: must differ'):
        monitor_config.from_section(Section(dict(load_yaml(path), peer='robot'), 'x'))
    with pytest.raises(ConfigError, match=r'probe_timeout: must be > probe_seconds \+ probe_omit \(4 s\)'):
        monitor_config.from_section(Section(dict(load_yaml(path), probe_timeout=4.0), 'x'))
    assert (cfg.probe.seconds, cfg.probe.omit, cfg.probe.cap) == (2, 2, 100000000)
