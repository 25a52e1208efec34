"""Link emulator scheduling and testbed configuration parsing (no root, no network)."""
import copy
import os
import random

import pytest
import yaml

from cnr_params import ConfigError, load_yaml
from cnr_testbed.core.config import load_link_map, load_testbed, load_trace
from cnr_testbed.core.link import Conditions, LinkDirection

TESTBED_YAML = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config', 'testbed.yaml')
#: an unimpaired link as config/testbed.yaml sets it
IDEAL = load_yaml(TESTBED_YAML)['testbed']['link']['both']


def cond(**changes):
    """Conditions: the configured unimpaired link with ``changes``."""
    return Conditions(**dict(IDEAL, **changes))


def run(link, times, size=1000):
    for i, t in enumerate(times):
        link.offer(bytes(size), t)


def test_fixed_delay():
    link = LinkDirection(cond(delay=50.0))
    link.offer(b'x' * 100, 1.0)
    assert link.next_due() == pytest.approx(1.05)
    assert link.due(1.049) == [] and len(link.due(1.05)) == 1


def test_jitter_keeps_order_unless_reorder():
    link = LinkDirection(cond(delay=20.0, jitter=10.0), random.Random(1))
    for i in range(200):
        link.offer(i.to_bytes(2, 'big'), i * 0.001)
    out = [int.from_bytes(p, 'big') for p in link.due(10.0)]
    assert out == list(range(200))
    link = LinkDirection(cond(delay=20.0, jitter=10.0, reorder=True), random.Random(1))
    for i in range(200):
        link.offer(i.to_bytes(2, 'big'), i * 0.001)
    out = [int.from_bytes(p, 'big') for p in link.due(10.0)]
    assert sorted(out) == list(range(200)) and out != list(range(200))


def test_jitter_spread():
    link = LinkDirection(cond(delay=50.0, jitter=5.0, reorder=True), random.Random(2))
    releases = []
    for i in range(2000):
        link.offer(b'p', 0.0)
    while link.next_due() is not None:
        t = link.next_due()
        releases += [t] * len(link.due(t))
    mean = sum(releases) / len(releases)
    std = (sum((r - mean) ** 2 for r in releases) / len(releases)) ** 0.5
    assert mean == pytest.approx(0.05, abs=0.001) and std == pytest.approx(0.005, rel=0.1)


def test_token_bucket_rate_and_bounded_queue():
    link = LinkDirection(cond(rate=8.0, queue=10))            # 8 Mbit/s: 1000 B in 1 ms
    for i in range(50):                                              # a burst of 50 packets at t = 0
        link.offer(bytes(1000), 0.0)
    assert link.counters.dropped_queue == 40
    times = []
    while link.next_due() is not None:
        t = link.next_due()
        times += [t] * len(link.due(t))
    assert times == pytest.approx([0.001 * (i + 1) for i in range(10)])
    # steady offered load above the rate: delivered throughput equals the rate
    link = LinkDirection(cond(rate=8.0, queue=20))
    for i in range(2000):
        link.offer(bytes(1000), i * 0.0005)                          # 16 Mbit/s offered
    delivered = len(link.due(1.0))
    assert delivered == pytest.approx(1000, abs=25)


def test_loss_rate_and_outage():
    link = LinkDirection(cond(loss=0.2), random.Random(3))
    for i in range(10000):
        link.offer(b'p', 0.0)
    assert link.counters.dropped_loss / 10000 == pytest.approx(0.2, abs=0.02)
    link.set(link.conditions.updated(outage=True))
    assert not link.offer(b'p', 1.0)


def test_conditions_validation():
    with pytest.raises(ValueError):
        cond(delay=-1.0).validate()
    with pytest.raises(ValueError):
        cond().updated(loss=1.5)
    with pytest.raises(ValueError):
        cond().updated(colour='red')


def test_repository_config_and_overrides(workspace):
    cfg = load_testbed(f'{workspace}/config/testbed.yaml', {'name': 't1', 'robot.namespace': 't1-robot'})
    assert cfg.name == 't1' and cfg.robot_ns == 't1-robot' and cfg.cloud_ns == 'cloud'
    assert cfg.robot_address == '10.77.0.1' and cfg.up.delay == 0.0
    lm = load_link_map(f'{workspace}/config/link_map_corridor.yaml')
    assert lm.conditions_at(0.5, 0.0)[0] == 'left_end' and lm.conditions_at(5.0, 0.0)[1].outage
    assert not lm.conditions_at(11.0, 0.0)[1].outage
    assert lm.direction == 'both'
    up = load_link_map(f'{workspace}/config/link_map_corridor_uplink.yaml')
    assert up.direction == 'up' and up.conditions_at(5.0, 0.0)[1].outage


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize('change, field', [
    (lambda t: t['cloud'].update(address='10.77.0.1'), 'address'),
    (lambda t: t['robot'].update(address='nope'), 'address'),
    (lambda t: t['link']['both'].update(delay=-5), 'delay'),
    (lambda t: t['robot'].update(namespace='bad name'), 'namespace'),
    (lambda t: t.pop('mtu'), 'testbed.mtu: missing'),
    (lambda t: t['robot'].pop('device'), 'testbed.robot.device: missing'),
    (lambda t: t['link']['both'].pop('queue'), 'testbed.link.both.queue: missing'),
    (lambda t: t.pop('sysctl'), 'testbed.sysctl: missing'),
    (lambda t: t.update(emulator_nice=-21), 'testbed.emulator_nice'),
    (lambda t: t['sysctl_if_available'].update({'vm.swappiness': 1}), 'testbed.sysctl_if_available.vm.swappiness'),
    (lambda t: t['sysctl'].update({'kernel.panic': 1}), 'testbed.sysctl.kernel.panic'),
    (lambda t: t['sysctl'].update({'net.ipv4.tcp_thin_linear_timeouts': 'yes'}), 'tcp_thin_linear_timeouts'),
])
def test_bad_testbed_config(tmp_path, change, field):
    doc = copy.deepcopy(load_yaml(TESTBED_YAML))
    change(doc['testbed'])
    with pytest.raises(ConfigError) as err:
        load_testbed(write(tmp_path, 'tb.yaml', yaml.safe_dump(doc)))
    assert field in str(err.value) and 'tb.yaml' in str(err.value)


def test_trace_parsing_and_errors(tmp_path):
    steps = load_trace(write(tmp_path, 'ok.tsv', 'time\tdirection\tdelay\toutage\n0\tboth\t10\t\n5\tup\t\ton\n'))
    assert [(s.time, s.direction, s.changes) for s in steps] == [(0.0, 'both', {'delay': 10.0}),
                                                                  (5.0, 'up', {'outage': True})]
    for text, field in [('t\tdirection\n', 'header'), ('time\tdirection\tdelay\n5\tboth\t1\n1\tboth\t2\n', 'time'),
                        ('time\tdirection\tdelay\n0\tsideways\t1\n', 'direction'),
                        ('time\tdirection\tdelay\n0\tboth\t-3\n', 'line 2'),
                        ('time\tdirection\tspeed\n', 'header')]:
        with pytest.raises(ConfigError) as err:
            load_trace(write(tmp_path, 'bad.tsv', text))
        assert field in str(err.value)


def test_link_map_direction_is_required_and_checked(tmp_path):
    base = {'default': IDEAL, 'regions': []}
    with pytest.raises(ConfigError, match='link_map.direction: missing'):
        load_link_map(write(tmp_path, 'lm.yaml', yaml.safe_dump({'link_map': base})))
    with pytest.raises(ConfigError, match='link_map.direction'):
        load_link_map(write(tmp_path, 'lm.yaml', yaml.safe_dump({'link_map': dict(base, direction='sideways')})))


def test_bad_link_map(tmp_path):
    with pytest.raises(ConfigError) as err:
        load_link_map(write(tmp_path, 'lm.yaml', yaml.safe_dump(
            {'link_map': {'default': IDEAL, 'regions': [{'name': 'a', 'x': [2, 1], 'y': [0, 1]}]}})))
    assert 'regions[0].x' in str(err.value)
    with pytest.raises(ConfigError, match='link_map.default.jitter: missing'):
        load_link_map(write(tmp_path, 'lm.yaml', 'link_map: {default: {delay: 1.0}, regions: []}'))
