"""bench_profile's statistics without ROS or a testbed: errors against the settings, spreads, targets, the
TSV round trip and the markdown report."""
import datetime
import math

import pytest

from cnr_benchmarks.core import profile as core


def sample(rtt, rate, rep, measured, a_bw=math.nan, passive=math.nan, ok=1, link=(1000000, 20000), probe_s=4.2):
    return core.Sample(set_rtt_ms=rtt, set_rate_mbit=rate, rep=rep, rtt_ms=measured, rtt_spread_ms=0.1,
                       probe_ok=ok, a_bw_mbit=a_bw, probe_s=probe_s, probe_iperf_bytes=990000,
                       probe_link_up_bytes=link[0], probe_link_down_bytes=link[1],
                       load_mbit=rate / 2 if rate else math.nan, passive_mbit=passive,
                       passive_age_s=10.2 if rate else math.nan, passive_method='passive' if rate else '',
                       usage_mbit=rate * 0.53 if rate else math.nan)


SAMPLES = [
    sample(0, 0, 1, 0.6, a_bw=99.7), sample(0, 0, 2, 0.7, a_bw=99.8),
    sample(0, 1, 1, 2.5, a_bw=0.93, passive=0.87), sample(0, 1, 2, 2.5, a_bw=0.93, passive=0.87),
    sample(150, 1, 1, 153.0, a_bw=0.94, passive=0.88), sample(150, 1, 2, 152.8, a_bw=26.4, passive=0.88),
    sample(150, 50, 1, 151.0, a_bw=48.2, passive=43.8), sample(150, 50, 2, 151.2, ok=0, passive=math.nan),
]


def test_baselines_are_medians_of_the_undelayed_cells():
    assert core.baseline_rtt_ms(SAMPLES) == pytest.approx(0.65)
    assert core.baseline_rtt_ms(SAMPLES, 1.0) == pytest.approx(2.5)
    assert math.isnan(core.baseline_rtt_ms(SAMPLES, 10.0))


def test_errors_spreads_and_targets_per_cell():
    cells = {(c.set_rtt_ms, c.set_rate_mbit): c for c in core.summarize_cells(SAMPLES, 0.65)}
    assert list(cells) == [(0, 0), (0, 1), (150, 1), (150, 50)]
    slow = cells[(150, 1)]
    assert slow.rtt_error_ms.lo == pytest.approx(2.15) and slow.rtt_error_ms.hi == pytest.approx(2.35)
    assert slow.delay_error_ms.mean == pytest.approx(0.4)          # serialisation at 1 Mbit/s taken out
    assert slow.a_bw_error_pct.hi == pytest.approx(2540.0)
    assert slow.met() == {'rtt': False, 'delay': True, 'a_bw': False, 'passive': True}
    fast = cells[(150, 50)]
    assert fast.probe_failures == 1 and fast.a_bw_mbit.n == 1 and fast.met()['a_bw'] is False
    assert fast.probe_mb.mean == pytest.approx(1.02) and fast.passive_error_pct.mean == pytest.approx(-12.4)
    assert cells[(0, 0)].met() == {'rtt': True, 'delay': True, 'a_bw': None, 'passive': None}
    assert core.totals(cells.values()) == {'rtt': (3, 4), 'delay': (3, 3), 'a_bw': (1, 3), 'passive': (3, 3)}


def test_spread_text():
    assert core.Spread.of([]).text() == '–'
    assert core.Spread.of([1.0, math.nan]).text('.2f') == '1.00'
    assert core.Spread.of([-1.0, 3.0]).text('.1f', signed=True) == '+1.0 [-1.0, +3.0]'


def test_tsv_round_trip_and_report(tmp_path):
    from cnr_benchmarks.profile_bench import write_outputs
    from cnr_benchmarks.report import TsvLog
    log = TsvLog(str(tmp_path / 'profile.tsv'), core.Sample.columns())
    for s in SAMPLES:
        log.row(**vars(s))
    log.close()
    text = write_outputs(str(tmp_path / 'profile.tsv'), str(tmp_path), 'launch_scripts/bench_profile.sh --quick',
                         datetime.datetime(2026, 1, 2, 3, 4), 90.0, 'test machine')
    assert (tmp_path / 'README.md').read_text() == text
    assert 'Baseline RTT' in text and '**0.65 ms**' in text and '1.5 min' in text and 'test machine' in text
    assert '| 150 | 1 | 152.90 [152.80, 153.00] | +2.25 [+2.15, +2.35] | +0.40 [+0.30, +0.50] |' in text
    assert 'A_bw ±10 % in 1/3' in text and '(1 failed)' in text


def test_the_page_names_the_probe_method(tmp_path):
    from cnr_benchmarks.profile_bench import write_outputs
    from cnr_benchmarks.report import TsvLog
    log = TsvLog(str(tmp_path / 'profile.tsv'), core.Sample.columns())
    for s in SAMPLES:
        log.row(**vars(s))
    log.close()
    train = write_outputs(str(tmp_path / 'profile.tsv'), str(tmp_path / 'train'),
                          'launch_scripts/bench_profile.sh --probe-method train', datetime.datetime(2026, 1, 2, 3, 4),
                          90.0, 'test machine', 'train')
    assert 'packet-train probe' in train.splitlines()[0] and 'Probe method: **train**' in train
    assert '60 × 1472 B = 88 KB' in train and 'iperf3 -t' not in train
    iperf3 = write_outputs(str(tmp_path / 'profile.tsv'), str(tmp_path / 'iperf3'), 'launch_scripts/bench_profile.sh',
                           datetime.datetime(2026, 1, 2, 3, 4), 90.0, 'test machine', 'iperf3')
    assert 'iperf3 probe' in iperf3.splitlines()[0] and 'Probe method: **iperf3**' in iperf3
    assert 'iperf3 -t 2 -O 2, at most 50 MB' in iperf3


def test_options_default_to_the_configured_method_and_its_page():
    from cnr_benchmarks import results
    from cnr_benchmarks.profile_bench import configured_probe_method, parse_args
    configured = configured_probe_method()
    _, args = parse_args([])
    assert args.probe_method == configured and args.reps == 2
    assert args.out == results.results_dir('profile' if configured == 'iperf3' else 'profile_train')
    _, args = parse_args(['--probe-method', 'train', '--quick'])
    assert args.probe_method == 'train' and args.reps == 1 and args.out == results.results_dir('profile_train')
    _, args = parse_args(['--probe-method', 'iperf3'])
    assert args.out == results.results_dir('profile')
    _, args = parse_args(['--probe-method', 'train', '--out', '/tmp/elsewhere'])
    assert args.out == '/tmp/elsewhere'


@pytest.mark.parametrize('argv', [['--probe-method', 'ping'], ['--reps', '0']])
def test_bad_options_exit_2(argv, capsys):
    from cnr_benchmarks.profile_bench import parse_args
    with pytest.raises(SystemExit) as exc:
        parse_args(argv)
    assert exc.value.code == 2 and len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.parametrize('method', ['iperf3', 'train'])
def test_monitor_overlays(method):
    from cnr_params import Section, load_yaml
    from network_monitor.core.config import from_section
    from cnr_benchmarks.profile_bench import monitor_config_path, monitor_overlays
    overlays = monitor_overlays(method, '10.9.0.1', '10.9.0.2')
    assert overlays['robot'] == dict(probe_interval=0.0, probe_method=method, peer_address='10.9.0.2')
    cloud = dict(probe_interval=0.0, probe_method=method, name='cloud', peer='robot', peer_address='10.9.0.1')
    if method == 'train':
        cloud['train_server'] = True          # the robot's monitor probes the cloud's responder
    assert overlays['cloud'] == cloud
    base = load_yaml(monitor_config_path())
    configs = {side: from_section(Section(dict(base, **overlay), side)) for side, overlay in overlays.items()}
    assert configs['robot'].probe_method == configs['cloud'].probe_method == method
    assert configs['cloud'].train_server == (method == 'train')
