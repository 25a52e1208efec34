"""The two battery packs without a master: the base's (base idle + motors) and the robot computer's (laptop idle +
CPU + radio), their messages, the task's B_task from the computer's and the results files' battery columns."""
import dataclasses
import os
import shutil

import pytest
import yaml

from cnr_params import ConfigError, Section
from cnr_sim.core.battery import (BASE_CONSUMERS, COMPUTER_CONSUMERS, BatteryConfig, BatteryModel, EnergyBreakdown)
from cnr_sim.params import config_section

WS = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
SIM = config_section(os.path.join(WS, 'config'))


def config(**changes) -> BatteryConfig:
    return dataclasses.replace(BatteryConfig.from_section(SIM.section('battery')), **changes)


def test_cpu_and_radio_drain_the_computer_pack_only():
    b = BatteryModel(config())
    b.add_work(cpu_seconds=20.0, bytes_transferred=50e6, interval=10.0)
    drawn = b.energy.cpu + b.energy.radio
    assert drawn > 0 and b.computer.drawn == pytest.approx(drawn)
    assert b.base.drawn == 0.0 and b.base.percentage == 100.0
    assert b.computer.percentage == pytest.approx(100.0 * (1 - drawn / b.computer.capacity_j))
    assert b.computer.power == pytest.approx(drawn / 10.0 + b.config.laptop_idle_power)
    assert b.base.power == 0.0


def test_motors_and_base_idle_drain_the_base_pack_only():
    still, moving = BatteryModel(config(laptop_idle_power=0.0)), BatteryModel(config(laptop_idle_power=0.0))
    for _ in range(500):
        still.step(0.02, 0.0, 0.0, 0.0, 0.0)
        moving.step(0.02, 0.5, 0.5, 0.0, 0.0)
    assert still.base.drawn == pytest.approx(still.config.base_idle_power * 10.0)
    assert moving.base.drawn == pytest.approx(still.base.drawn + moving.energy.motors) and moving.energy.motors > 0
    assert moving.base.percentage < still.base.percentage < 100.0
    assert still.computer.percentage == moving.computer.percentage == 100.0
    assert moving.base.power > still.base.power > 0 and moving.computer.power == 0.0
    # the laptop's idle draw goes to the computer's pack, not the base's
    laptop = BatteryModel(config(base_idle_power=0.0))
    laptop.step(10.0, 0.0, 0.0, 0.0, 0.0)
    assert laptop.base.drawn == 0.0 and laptop.computer.drawn == pytest.approx(10.0 * laptop.config.laptop_idle_power)


def test_each_pack_percentage_from_its_own_capacity():
    cfg = config(base_idle_power=1.0, laptop_idle_power=1.0)
    b = BatteryModel(cfg)
    b.step(1000.0, 0.0, 0.0, 0.0, 0.0)                 # 1000 J from each pack
    base, computer = cfg.base_pack, cfg.computer_pack
    assert b.base.percentage == pytest.approx(100.0 - 1000.0 / (base.capacity_ah * 3600 * base.nominal_voltage) * 100)
    assert b.computer.percentage == pytest.approx(
        100.0 - 1000.0 / (computer.capacity_ah * 3600 * computer.nominal_voltage) * 100)
    assert b.base.percentage != pytest.approx(b.computer.percentage)
    assert b.computer.charge_ah == pytest.approx(b.computer.percentage / 100 * computer.capacity_ah)
    big = BatteryModel(dataclasses.replace(cfg, computer_pack=dataclasses.replace(
        computer, capacity_ah=2 * computer.capacity_ah, initial_percentage=50.0)))
    big.step(1000.0, 0.0, 0.0, 0.0, 0.0)
    assert 50.0 - big.computer.percentage == pytest.approx((100.0 - b.computer.percentage) / 2)


def test_pack_voltages_follow_their_mappings():
    """Kobuki: kobuki_driver's % = 95 (V - 13.2) / 3.3 + 5; the netbook: linear from 9.0 V (0 %) to 12.6 V."""
    b = BatteryModel(config())
    assert b.base.voltage == pytest.approx(16.5) and b.computer.voltage == pytest.approx(12.6)
    b.energy.motors = 0.5 * b.base.capacity_j
    b.energy.cpu = 0.25 * b.computer.capacity_j
    assert b.base.percentage == pytest.approx(50.0)
    assert 95 * (b.base.voltage - 13.2) / (16.5 - 13.2) + 5 == pytest.approx(50.0)
    assert b.computer.voltage == pytest.approx(9.0 + 0.75 * 3.6)
    b.energy.cpu = 2 * b.computer.capacity_j
    assert b.computer.percentage == 0.0 and b.computer.voltage == pytest.approx(9.0)
    b.computer.power = 12.0
    assert b.computer.current == pytest.approx(-12.0 / 9.0)


def test_consumers_partition_the_breakdown():
    assert set(BASE_CONSUMERS) | set(COMPUTER_CONSUMERS) == {f.name for f in dataclasses.fields(EnergyBreakdown)}
    assert not set(BASE_CONSUMERS) & set(COMPUTER_CONSUMERS)
    b = BatteryModel(config())
    b.step(0.5, 0.3, 0.2, 0.1, 0.1)
    b.add_work(1.0, 1000, 1.0)
    assert b.base.drawn + b.computer.drawn == pytest.approx(b.energy.total)
    assert b.energy.idle == pytest.approx(b.energy.base_idle + b.energy.laptop_idle)
    assert list(b.computer.breakdown) == list(COMPUTER_CONSUMERS)


def test_pack_configuration_errors_name_the_field():
    sec = SIM.section('battery')
    cfg = BatteryConfig.from_section(sec)
    assert (cfg.base_pack.topic, cfg.computer_pack.topic) == ('battery_state', 'laptop_charge')
    assert cfg.computer_pack.capacity_ah == 5.2 and cfg.computer_pack.nominal_voltage == 10.8

    def with_pack(name, **values):
        return Section(dict(sec.data, **{name: dict(sec.data[name], **values)}), 'battery.yaml')

    with pytest.raises(ConfigError, match='computer_pack.capacity_ah'):
        BatteryConfig.from_section(with_pack('computer_pack', capacity_ah=-1.0))
    with pytest.raises(ConfigError, match='base_pack.full_voltage'):
        BatteryConfig.from_section(with_pack('base_pack', full_voltage=13.0))
    with pytest.raises(ConfigError, match='computer_pack.topic'):
        BatteryConfig.from_section(with_pack('computer_pack', topic='battery_state'))
    with pytest.raises(ConfigError, match='computer_pack: missing'):
        BatteryConfig.from_section(Section({k: v for k, v in sec.data.items() if k != 'computer_pack'}, 'b.yaml'))
    without = {k: v for k, v in sec.data['base_pack'].items() if k != 'initial_percentage'}
    with pytest.raises(ConfigError, match='base_pack.initial_percentage: missing'):
        BatteryConfig.from_section(Section(dict(sec.data, base_pack=without), 'battery.yaml'))


def test_each_pack_is_published_as_its_own_battery_state():
    import rospy
    from sensor_msgs.msg import BatteryState
    from cnr_sim.node import SimulatorNode
    b = BatteryModel(config())
    b.step(10.0, 0.5, 0.0, 0.0, 0.0)
    b.add_work(2.0, 1e6, 10.0)
    base = SimulatorNode._battery_msg(rospy.Time(10), b.base)
    computer = SimulatorNode._battery_msg(rospy.Time(10), b.computer)
    assert isinstance(computer, BatteryState)
    assert (base.location, computer.location) == ('kobuki', 'netbook')
    assert base.percentage == pytest.approx(b.base.percentage / 100)
    assert computer.percentage == pytest.approx(b.computer.percentage / 100) and computer.capacity == 5.2
    assert computer.voltage == pytest.approx(b.computer.voltage) and computer.current < 0
    assert 'cpu=' in computer.serial_number and 'motors' not in computer.serial_number
    assert 'motors=' in base.serial_number and 'cpu' not in base.serial_number


def test_task_b_task_is_the_computer_pack_and_b_base_the_base_pack():
    from cnr_mission.core.task import battery_fields
    fields = battery_fields(computer=(0.9, 0.895), base=(0.8, 0.79))
    assert fields['b_task'] == pytest.approx(0.005) and fields['b_base'] == pytest.approx(0.01)
    assert battery_fields(computer=(None, 0.9), base=(0.8, 0.79))['b_task'] != fields['b_task']   # NaN
    # the runner reads the topics the simulator publishes the packs on (both in the root namespace)
    with open(os.path.join(WS, 'config', 'task_runner.yaml')) as f:
        runner = yaml.safe_load(f)
    cfg = BatteryConfig.from_section(SIM.section('battery'))
    assert runner['battery_topic'] == '/' + cfg.computer_pack.topic
    assert runner['base_battery_topic'] == '/' + cfg.base_pack.topic


def test_a_decided_runs_b_task_counts_its_placement_and_a_pack_is_read_between_readings():
    from cnr_mission.core.task import battery_fields, charge_at
    readings = [(10.0, 0.90), (11.0, 0.89), (12.0, 0.88)]
    assert charge_at(readings, 9.5) is None                           # before the first reading: unknown
    assert charge_at(readings, 10.0) == pytest.approx(0.90)
    assert charge_at(readings, 10.25) == pytest.approx(0.8975)        # between the two around it
    assert charge_at(readings, 12.7) == pytest.approx(0.88)           # after the last: the last
    assert charge_at([(5.0, 0.5), (5.0, 0.4)], 5.0) == pytest.approx(0.4)
    fields = battery_fields(computer=(0.89, 0.80), base=(0.7, 0.69), decided=True, at_placing=0.895,
                            at_profile=0.8975)
    assert fields['b_task'] == pytest.approx(0.095) and fields['b_decision'] == pytest.approx(0.0075)
    assert fields['b_base'] == pytest.approx(0.01)                    # the base's: the drive alone
    no_reading = battery_fields(computer=(0.89, 0.80), base=(0.7, 0.69), decided=True, at_placing=None)
    assert no_reading['b_task'] != no_reading['b_task']               # NaN: the run is invalid
    assert 'b_decision' not in battery_fields(computer=(0.89, 0.80), base=(0.7, 0.69))   # a control run


def test_results_files_with_one_pack_are_read_and_appended_in_their_columns(tmp_path):
    from cnr_mission.core.task import RESULT_COLUMNS, RESULT_COLUMNS_ONE_PACK, append_result, read_results
    committed = os.path.join(WS, 'docs', 'results', 'campaign', 'results.tsv')
    old = str(tmp_path / 'old.tsv')
    shutil.copy(committed, old)
    rows, warnings = read_results(old)
    assert rows and not warnings and all(r['b_base'] == '' and r['b_task'] for r in rows)
    append_result(old, dict(id='x', condition='c', b_task=0.005, b_base=0.01))
    with open(old) as f:
        lines = f.read().splitlines()
    assert lines[0].split('\t') == list(RESULT_COLUMNS_ONE_PACK)
    assert len(lines[-1].split('\t')) == len(RESULT_COLUMNS_ONE_PACK)
    again, warnings = read_results(old)
    assert not warnings and len(again) == len(rows) + 1 and again[-1]['b_task'] == '0.005'
    new = str(tmp_path / 'new.tsv')
    append_result(new, dict(id='y', condition='c', b_task=0.005, b_base=0.01))
    (row,), _ = read_results(new)
    assert row['b_base'] == '0.01' and list(row) == list(RESULT_COLUMNS)
    # two packs, from before the decision's cost was counted: b_base read, t_decision and b_decision empty
    two = tmp_path / 'two.tsv'
    two_columns = [c for c in RESULT_COLUMNS if c not in ('t_decision', 'b_decision')]
    two.write_text('\t'.join(two_columns) + '\n' + '\t'.join('0.01' if c == 'b_base' else 'v' for c in two_columns)
                   + '\n')
    (row,), warnings = read_results(str(two))
    assert not warnings and row['b_base'] == '0.01' and row['t_decision'] == '' and list(row) == list(RESULT_COLUMNS)
    append_result(str(two), dict(id='w', condition='c', b_task=0.005, t_decision=0.4))
    assert two.read_text().splitlines()[-1].split('\t') == [
        'w' if c == 'id' else 'c' if c == 'condition' else '0.005' if c == 'b_task' else '' for c in two_columns]
    bad = tmp_path / 'bad.tsv'
    bad.write_text('id\tcondition\n')
    with pytest.raises(ConfigError, match='header'):
        read_results(str(bad))
    shuffled = tmp_path / 'shuffled.tsv'      # every column, but not in their order
    shuffled.write_text('\t'.join(reversed(RESULT_COLUMNS)) + '\n')
    with pytest.raises(ConfigError, match='header'):
        read_results(str(shuffled))
    with pytest.raises(ConfigError, match='header'):
        append_result(str(bad), dict(id='z'))


def test_mission_b_task_and_summary_per_pack():
    """The mission monitor keeps each pack's readings; its B_task is the computer pack's, to the hotspot."""
    import math
    from types import SimpleNamespace as Msg
    from cnr_mission.core.report import PackReadings

    def reading(t, percentage, charge):
        return Msg(header=Msg(stamp=t), percentage=percentage, charge=charge, serial_number=f'cpu={t}J')

    pack = PackReadings()
    assert math.isnan(pack.used_to_hotspot()) and pack.used() is None
    pack.add(reading(1, 0.99, 5.148))
    pack.add(reading(2, 0.985, 5.122))
    pack.add(reading(3, 0.98, 5.096), hotspot_stamp=3)       # the first reading from the hotspot's time on
    pack.add(reading(4, 0.97, 5.044), hotspot_stamp=3)
    assert pack.used_to_hotspot() == pytest.approx(0.01)
    used = pack.used()
    assert used['used_percent'] == pytest.approx(2.0) and used['used_ah'] == pytest.approx(0.104)
    assert used['energy'] == 'cpu=4J'
    without = PackReadings()
    without.add(reading(1, 0.99, 5.148))
    without.add(reading(2, 0.97, 5.044))
    assert without.used_to_hotspot() == pytest.approx(0.02)                  # no hotspot: to the last reading


def test_a_task_s_first_result_makes_its_folder(tmp_path):
    """The first run of a task with no results yet (e.g. exp_control.sh --task corridor_long) writes into a folder
    that does not exist: made, not a FileNotFoundError in the task runner."""
    from cnr_mission.core.task import append_result, read_results
    path = tmp_path / 'control' / 'corridor_long@corridor' / 'results.tsv'
    append_result(str(path), dict(id='control-01', condition='c', b_task=0.003, b_base=0.01))
    rows, warnings = read_results(str(path))
    assert [r['id'] for r in rows] == ['control-01'] and not warnings
