"""The battery's work meters without a master: CPU by cgroup, totals of charged work, the parameter."""
import os

import pytest

from cnr_params import ConfigError, Section
from cnr_sim.core.battery import BatteryConfig, BatteryModel, CgroupCpuMeter, CpuMeter, NetMeter, cpu_meter
from cnr_sim.params import config_section, read_params
from cnr_testbed.cpucap import UsageReader

SIM = config_section(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'config'))
LAUNCH = dict(map_file='corridor.yaml', real_time_factor=1.0, initial_pose=[0.5, 0.0, 0.0])


class FakeReader:
    """Stands in for cnr_testbed.cpucap.UsageReader: returns the given readings (None = unreadable)."""

    def __init__(self, readings):
        self.readings = list(readings)
        self.problem = ''

    def read(self):
        value = self.readings.pop(0)
        self.problem = '' if value is not None else 'cgroup x: absent'
        return value


def meter(readings):
    return CgroupCpuMeter(FakeReader(readings))


def test_cgroup_meter_charges_usage_deltas():
    m = meter([10.0, 10.5, 12.0])
    assert m.sample() == 0.0              # the work before the simulator started is not charged
    assert m.sample() == pytest.approx(0.5)
    assert m.sample() == pytest.approx(1.5)
    assert not m.needs_pids and m.problem == ''


def test_cgroup_meter_group_appearing_late_or_recreated():
    m = meter([None, 0.75, 1.0, 0.25])
    assert m.sample() == 0.0 and 'absent' in m.problem
    assert m.sample() == pytest.approx(0.75)   # created after the simulator started: charged from its creation
    assert m.sample() == pytest.approx(0.25)
    assert m.sample() == pytest.approx(0.25)   # re-created: its usage restarted from 0


def test_meter_choice_follows_the_parameter():
    assert isinstance(cpu_meter('', UsageReader), CpuMeter) and cpu_meter('', UsageReader).needs_pids
    assert isinstance(cpu_meter('cnr_robot_cnr', UsageReader), CgroupCpuMeter)
    with pytest.raises(ValueError):
        cpu_meter('../escape', UsageReader)


def test_model_totals_of_charged_work():
    b = BatteryModel(BatteryConfig.from_section(SIM.section('battery')))
    b.add_work(0.5, 1000, 1.0)
    b.add_work(0.25, 24, 1.0)
    b.add_work(-1.0, -5, 1.0)                  # never negative
    assert b.cpu_seconds == pytest.approx(0.75) and b.radio_bytes == 1024
    c = b.config
    assert b.energy.cpu == pytest.approx(0.75 * c.cpu_full_load_power / c.cpu_capacity)
    assert b.energy.radio == pytest.approx(1024 * c.radio_joules_per_byte)


def test_cpu_cgroup_parameter_is_required_and_empty_by_default():
    data = dict(SIM.data, **LAUNCH)
    assert read_params(Section(data, '/simulator')).battery_cpu_cgroup == ''        # config/battery.yaml
    bat = {k: v for k, v in data['battery'].items() if k != 'cpu_cgroup'}
    with pytest.raises(ConfigError, match='battery.cpu_cgroup: missing'):
        read_params(Section(dict(data, battery=bat), '/simulator'))


def test_net_meter_counts_this_namespace():
    """psutil reads /proc/net/dev: the interfaces of this process's network namespace."""
    import psutil
    names = set(psutil.net_io_counters(pernic=True))
    with open('/proc/self/net/dev') as f:
        assert names == {line.split(':')[0].strip() for line in f.readlines()[2:]}
    m = NetMeter('no-such-device')
    assert m.sample() == 0 and m.sample() == 0
