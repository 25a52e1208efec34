"""The robot CPU cap's pure part and its file formats (no cgroup needed: a fake tree in tmp_path).

The real cgroups are exercised in test_cnr_testbed_cpucap_integration.py (root).
"""
from __future__ import annotations

import copy
import os

import pytest
import yaml

from cnr_params import ConfigError, load_yaml
from cnr_testbed.core import cpucap as core
from cnr_testbed.core.config import load_testbed
from cnr_testbed.core.cpucap import Layout, NoCgroup
from cnr_testbed.cpucap import CpuCgroup

HERE = os.path.dirname(os.path.abspath(__file__))
TESTBED_YAML = os.path.join(HERE, '..', 'config', 'testbed.yaml')

# this machine (cgroup v1, cpu and cpuacct mounted apart, a hybrid v2 without controllers)
V1_APART = """31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755
32 31 0:29 / /sys/fs/cgroup/cpu rw,relatime - cgroup cgroup rw,cpu
33 31 0:30 / /sys/fs/cgroup/cpuacct rw,relatime - cgroup cgroup rw,cpuacct
35 31 0:32 / /sys/fs/cgroup/memory rw,relatime - cgroup cgroup rw,memory
41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw
"""
# systemd on cgroup v1 (Ubuntu 20.04): cpu and cpuacct co-mounted, with an optional field before the '-'
V1_TOGETHER = """25 22 0:23 / /sys/fs/cgroup ro,nosuid,nodev,noexec shared:9 - tmpfs tmpfs ro,mode=755
34 25 0:29 / /sys/fs/cgroup/cpu,cpuacct rw,nosuid,nodev,noexec,relatime shared:15 - cgroup cgroup rw,cpu,cpuacct
"""
V2_ONLY = """30 24 0:26 / /sys/fs/cgroup rw,nosuid,nodev,noexec,relatime shared:4 - cgroup2 cgroup2 rw,nsdelegate
"""


def test_mountinfo_parsing_and_escapes():
    mounts = core.parse_mountinfo(V1_APART + 'garbage line\n' +
                                  r'50 31 0:40 / /mnt/with\040space rw - cgroup cgroup rw,pids' + '\n')
    assert [m.point for m in mounts][-1] == '/mnt/with space'
    assert mounts[1] == core.Mount('/', '/sys/fs/cgroup/cpu', 'cgroup', ('rw', 'cpu'))
    assert core.v1_hierarchy(mounts, 'cpuacct') == '/sys/fs/cgroup/cpuacct'
    assert core.v2_mount(mounts) == '/sys/fs/cgroup/unified'


def test_layout_choice():
    apart = core.choose_layout(core.parse_mountinfo(V1_APART), '')
    assert apart == Layout(1, '/sys/fs/cgroup/cpu', '/sys/fs/cgroup/cpuacct')
    assert apart.hierarchies() == ['/sys/fs/cgroup/cpu', '/sys/fs/cgroup/cpuacct']
    together = core.choose_layout(core.parse_mountinfo(V1_TOGETHER), '')
    assert together == Layout(1, '/sys/fs/cgroup/cpu,cpuacct', '/sys/fs/cgroup/cpu,cpuacct')
    assert together.hierarchies() == ['/sys/fs/cgroup/cpu,cpuacct']
    v2 = core.choose_layout(core.parse_mountinfo(V2_ONLY), 'cpuset cpu io memory pids\n', prefix='/proc/7/root')
    assert v2 == Layout(2, '/proc/7/root/sys/fs/cgroup', '/proc/7/root/sys/fs/cgroup')
    with pytest.raises(NoCgroup, match='no cpu controller'):
        core.choose_layout(core.parse_mountinfo(V2_ONLY), 'memory pids')
    with pytest.raises(NoCgroup, match='no cgroup v1 cpu hierarchy and no cgroup v2'):
        core.choose_layout([], '')


def test_names():
    assert core.default_name('cnr') == 'cnr_robot_cnr'
    for bad in ('', '..', 'a/b', 'x' * 65, 'sp ace'):
        with pytest.raises(ValueError):
            core.check_name(bad)


def test_quota_and_shortest_period():
    assert core.quota_us(0.25, 10000) == 2500
    assert core.quota_us(1 / 8.6, 10000) == 1163
    assert core.quota_us(1.5, 100000) == 150000          # more than one CPU's worth is allowed
    assert core.shortest_period_us(1 / 8.6) == 8600
    assert core.shortest_period_us(0.25) == 4000 and core.shortest_period_us(2.0) == 1000
    with pytest.raises(ValueError, match='at least 8600 us'):
        core.quota_us(1 / 8.6, 5000)
    for cpus, period in ((0.5, 999), (0.5, 1000001), (0.0, 10000), (float('nan'), 10000), (0.5, 10000.0)):
        with pytest.raises(ValueError):
            core.quota_us(cpus, period)


def test_limit_file_formats_round_trip():
    v1 = core.limit_files(1, 0.25, 10000)
    assert v1 == [('cpu.cfs_period_us', '10000'), ('cpu.cfs_quota_us', '2500')]
    assert core.parse_limit(1, dict(v1)) == (0.25, 10000)
    assert core.limit_files(1, None, 100000)[1] == ('cpu.cfs_quota_us', '-1')
    assert core.parse_limit(1, {'cpu.cfs_period_us': '100000\n', 'cpu.cfs_quota_us': '-1\n'}) == (None, 100000)
    v2 = core.limit_files(2, 0.25, 10000)
    assert v2 == [('cpu.max', '2500 10000')]
    assert core.parse_limit(2, dict(v2)) == (0.25, 10000)
    assert core.limit_files(2, None, 100000) == [('cpu.max', 'max 100000')]
    assert core.parse_limit(2, {'cpu.max': 'max 100000\n'}) == (None, 100000)


def test_usage_and_throttling_parsing():
    assert core.usage_seconds(1, '1500000000\n') == 1.5
    stat2 = 'usage_usec 2500000\nuser_usec 2000000\nsystem_usec 500000\nnr_periods 10\nnr_throttled 4\n' \
            'throttled_usec 30000\n'
    assert core.usage_seconds(2, stat2) == 2.5
    with pytest.raises(ValueError):
        core.usage_seconds(2, 'nr_periods 3\n')
    t1 = core.throttling(1, 'nr_periods 100\nnr_throttled 25\nthrottled_time 2000000000\nnr_bursts 0\n')
    assert (t1.periods, t1.throttled, t1.throttled_seconds, t1.throttled_fraction) == (100, 25, 2.0, 0.25)
    t2 = core.throttling(2, stat2)
    assert (t2.periods, t2.throttled, t2.throttled_seconds) == (10, 4, 0.03)
    assert core.throttling(1, '').throttled_fraction == 0.0
    assert core.parse_flat_keyed('a 1\nbad\nb x\nc 3 4\n') == {'a': 1}
    assert core.parse_pids('12\n345\n') == [12, 345]


def _fake_root(tmp_path, *names):
    for n in names:
        (tmp_path / n).mkdir()
    return str(tmp_path)


def test_v1_files_on_a_fake_tree(tmp_path):
    root = _fake_root(tmp_path, 'cpu', 'cpuacct')
    cg = CpuCgroup(Layout(1, f'{root}/cpu', f'{root}/cpuacct'), 'cnr_robot_t')
    assert not cg.exists()
    cg.create(0.25, 10000)
    assert cg.exists() and os.path.isdir(f'{root}/cpuacct/cnr_robot_t')
    assert (tmp_path / 'cpu/cnr_robot_t/cpu.cfs_quota_us').read_text() == '2500'
    assert cg.limit() == (0.25, 10000)
    cg.add(4242)
    assert (tmp_path / 'cpu/cnr_robot_t/cgroup.procs').read_text() == '4242'
    assert (tmp_path / 'cpuacct/cnr_robot_t/cgroup.procs').read_text() == '4242'
    assert cg.pids() == [4242]
    (tmp_path / 'cpuacct/cnr_robot_t/cpuacct.usage').write_text('3000000000\n')
    (tmp_path / 'cpu/cnr_robot_t/cpu.stat').write_text('nr_periods 8\nnr_throttled 2\nthrottled_time 5000000\n')
    assert cg.usage_seconds() == 3.0 and cg.throttling().throttled == 2
    st = cg.status()
    assert st['cpus'] == 0.25 and st['usage_seconds'] == 3.0 and st['pids'] == [4242]


def test_v1_without_cpuacct_has_no_usage(tmp_path):
    root = _fake_root(tmp_path, 'cpu')
    cg = CpuCgroup(Layout(1, f'{root}/cpu', None), 'g')
    cg.create(0.5, 10000)
    with pytest.raises(NoCgroup, match='cpuacct'):
        cg.usage_seconds()


def test_v2_files_on_a_fake_tree(tmp_path):
    (tmp_path / 'cgroup.subtree_control').write_text('memory pids\n')
    cg = CpuCgroup(Layout(2, str(tmp_path), str(tmp_path)), 'cnr_robot_t')
    cg.create(1 / 8.6, 10000)
    assert (tmp_path / 'cgroup.subtree_control').read_text() == '+cpu'      # enabled for the children
    assert (tmp_path / 'cnr_robot_t/cpu.max').read_text() == '1163 10000'
    assert cg.dirs == [str(tmp_path / 'cnr_robot_t')]
    cg.add(77)
    assert (tmp_path / 'cnr_robot_t/cgroup.procs').read_text() == '77'
    (tmp_path / 'cnr_robot_t/cpu.stat').write_text('usage_usec 1250000\nnr_periods 2\nnr_throttled 1\n'
                                                   'throttled_usec 9000\n')
    assert cg.usage_seconds() == 1.25 and cg.throttling().throttled_seconds == 0.009
    cg.set_limit(None, 20000)
    assert cg.limit() == (None, 20000)


def test_repository_config_robot_cpu():
    rc = load_testbed(TESTBED_YAML).robot_cpu
    assert rc.enabled and rc.slowdown == pytest.approx(3.0) and rc.period_us == 10000
    assert core.quota_us(rc.cpus, rc.period_us) >= core.MIN_QUOTA_US


@pytest.mark.parametrize('change, message', [
    (lambda r: r.pop('slowdown'), 'testbed.robot_cpu.slowdown: missing'),
    (lambda r: r.pop('enabled'), 'testbed.robot_cpu.enabled: missing'),
    (lambda r: r.update(slowdown=0), 'testbed.robot_cpu.slowdown: must be > 0'),
    (lambda r: r.update(period_us=2000), 'testbed.robot_cpu.period_us: quota'),
    (lambda r: r.update(period_us=2000000), 'testbed.robot_cpu.period_us: must be <= 1000000'),
])
def test_bad_robot_cpu_config(tmp_path, change, message):
    doc = copy.deepcopy(load_yaml(TESTBED_YAML))
    change(doc['testbed']['robot_cpu'])
    path = tmp_path / 'tb.yaml'
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_testbed(str(path))
    assert message in str(err.value) and 'tb.yaml' in str(err.value) and '\n' not in str(err.value)


def test_missing_robot_cpu_section(tmp_path):
    doc = copy.deepcopy(load_yaml(TESTBED_YAML))
    del doc['testbed']['robot_cpu']
    path = tmp_path / 'tb.yaml'
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match='testbed.robot_cpu: missing'):
        load_testbed(str(path))


def test_process_labels_for_the_cpu_breakdown():
    assert core.process_label(['/usr/bin/python3', '/opt/ws/nodes/mfg_node', '__name:=mfg', '__log:=x']) == 'mfg'
    assert core.process_label(['/usr/bin/python3', '/usr/bin/rosmaster', '--core', '-p', '11411']) == 'rosmaster'
    assert core.process_label(['/usr/bin/python3', '-u', '/usr/bin/roslaunch', 'a.launch']) == 'roslaunch'
    assert core.process_label(['iperf3', '-s']) == 'iperf3'
    assert core.process_label([]) == ''


def test_a_group_breaks_its_cpu_down_by_process(tmp_path):
    """The pids of a group's cgroup.procs, labelled and summed (this test's own process stands in for a node)."""
    d = tmp_path / 'cpu' / 'g'
    d.mkdir(parents=True)
    (d / 'cgroup.procs').write_text(f'{os.getpid()}\n999999999\n')       # the second: no such process
    cg = CpuCgroup(Layout(1, str(tmp_path / 'cpu'), None), 'g')
    totals = cg.by_process()
    assert list(totals) == [core.process_label(open('/proc/self/cmdline').read().split('\0')[:-1]) or 'python3']
    assert next(iter(totals.values())) > 0


def test_cpu_shares_over_a_window():
    before = {10: ('move_base', 5.0), 11: ('bridge', 2.0), 12: ('rosout', 1.0), 13: ('mfg', 3.0)}
    after = {10: ('move_base', 7.0), 11: ('bridge', 2.5), 14: ('mfg', 0.4), 15: ('mfg', 0.1),
             13: ('other', 9.0)}                                   # pid 13 reused by another program
    shares = core.cpu_shares(before, after, 10.0)
    assert shares == pytest.approx({'move_base': 0.2, 'bridge': 0.05, 'mfg': 0.05, 'other': 0.9})
    assert list(shares)[0] == 'other'                              # largest first
    with pytest.raises(ValueError):
        core.cpu_shares(before, after, 0.0)
