"""Batteries of the TurtleBot 2 with a drain model whose inputs are measured.

ROS-free. Two packs, as on the real robot: the Kobuki base's (14.8 V Li-ion) feeds the base, the robot
computer's (the netbook's own battery, BAT0) feeds the computer. Power drawn [W]:

    base pack:      P_base_idle                                           (constant, from config)
                  + (m g c_rr |v| + m |a v| + I |alpha w| + c_turn |w|) / eta   (motors, from the simulated motion)
    computer pack:  P_laptop_idle                                         (constant, from config)
                  + E_cpu, E_radio as measured (below)
    E_cpu   = P_cpu / capacity * (CPU seconds actually used by the robot's computer: the processes of its cgroup,
                        read from the cgroup's accounting, or else the robot's processes, measured with psutil)
              P_cpu: the robot CPU's power above idle at full load [W]; capacity: the CPUs of this machine
              that are the robot's computer at full load (its cgroup's limit under the testbed's cap, 1/slowdown:
              a capped robot busy all the time uses ``capacity`` CPU-seconds per second and draws P_cpu)
    E_radio = e_byte * (bytes actually sent + received on the robot's interface, measured with psutil in the
                        caller's network namespace)

Energy integrates over sim time for the idle and motor terms; the CPU and radio terms are energy for work
that really happened, so they do not depend on the real-time factor. Each pack's state of charge drops by
the energy of its consumers over its own capacity (Ah x V_nominal); its reported voltage is linear in the
state of charge between ``empty_voltage`` (at ``percentage_at_empty_voltage``) and ``full_voltage`` (100 %):
for the Kobuki kobuki_driver's mapping (battery.cpp: % = 95 (V - 13.2) / (16.5 - 13.2) + 5).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, Optional, Set, Tuple, Union

from cnr_params import Section

from cnr_sim.core.plugins import CpuUsage

GRAVITY = 9.81  # m/s^2

#: the consumers each pack feeds (fields of :class:`EnergyBreakdown`)
BASE_CONSUMERS = ('base_idle', 'motors')
COMPUTER_CONSUMERS = ('laptop_idle', 'cpu', 'radio')


@dataclass
class PackConfig:
    """One battery pack (``battery.base_pack`` / ``battery.computer_pack`` in config/battery.yaml)."""

    topic: str                          # sensor_msgs/BatteryState topic the pack is published on
    location: str                       # BatteryState.location
    capacity_ah: float
    nominal_voltage: float
    full_voltage: float
    empty_voltage: float
    percentage_at_empty_voltage: float  # % the pack reports at empty_voltage (Kobuki: 5)
    initial_percentage: float

    @classmethod
    def from_section(cls, s: Section) -> 'PackConfig':
        """The pack's constants from ``s`` (a missing or bad one is a ConfigError naming it)."""
        cfg = cls(topic=s.string('topic'), location=s.string('location'),
                  capacity_ah=s.number('capacity_ah', positive=True),
                  nominal_voltage=s.number('nominal_voltage', positive=True),
                  full_voltage=s.number('full_voltage', positive=True),
                  empty_voltage=s.number('empty_voltage', nonnegative=True),
                  percentage_at_empty_voltage=s.number('percentage_at_empty_voltage', minimum=0.0, maximum=99.0),
                  initial_percentage=s.number('initial_percentage', minimum=0.0, maximum=100.0))
        if not cfg.topic:
            raise s.error('topic', 'must name a topic')
        if not cfg.full_voltage > cfg.empty_voltage:
            raise s.error('full_voltage', 'must be greater than empty_voltage')
        return cfg


@dataclass
class BatteryConfig:
    """Constants of the model (every one set in config/battery.yaml with its source)."""

    base_pack: PackConfig
    computer_pack: PackConfig
    base_idle_power: float
    laptop_idle_power: float
    mass: float
    rolling_resistance: float
    yaw_inertia: float
    turn_resistance_power: float
    motor_efficiency: float
    cpu_full_load_power: float
    cpu_capacity: float
    radio_joules_per_byte: float

    @classmethod
    def from_section(cls, s: Section) -> 'BatteryConfig':
        """Every constant from ``s`` (a missing one is a ConfigError naming it)."""
        kw = {name: s.number(name, nonnegative=True) for name in cls.__dataclass_fields__
              if name not in ('base_pack', 'computer_pack')}
        cfg = cls(base_pack=PackConfig.from_section(s.section('base_pack')),
                  computer_pack=PackConfig.from_section(s.section('computer_pack')), **kw)
        for key in ('motor_efficiency', 'cpu_capacity'):
            if not getattr(cfg, key) > 0:
                raise s.error(key, 'must be > 0')
        if cfg.base_pack.topic == cfg.computer_pack.topic:
            raise s.error('computer_pack.topic', f"must differ from base_pack.topic ('{cfg.base_pack.topic}')")
        return cfg


@dataclass
class EnergyBreakdown:
    """Energy used so far per consumer [J]."""

    base_idle: float = 0.0
    motors: float = 0.0
    laptop_idle: float = 0.0
    cpu: float = 0.0
    radio: float = 0.0

    @property
    def idle(self) -> float:
        """Both packs' idle draw [J]."""
        return self.base_idle + self.laptop_idle

    @property
    def total(self) -> float:
        return self.base_idle + self.motors + self.laptop_idle + self.cpu + self.radio


class Pack:
    """One pack's state: ``percentage``/``voltage``/``charge_ah``/``current`` from the energy of its consumers.

    Args:
        config: its constants.
        energy: the model's breakdown, of which the pack feeds ``consumers``.
        consumers: fields of ``energy``.
    """

    def __init__(self, config: PackConfig, energy: EnergyBreakdown, consumers: Tuple[str, ...]) -> None:
        self.config = config
        self.consumers = consumers
        self.capacity_j = config.capacity_ah * 3600.0 * config.nominal_voltage
        self.power = 0.0          # latest power drawn from the pack [W]
        self._energy = energy

    @property
    def drawn(self) -> float:
        """Energy drawn from the pack so far [J]."""
        return sum(getattr(self._energy, k) for k in self.consumers)

    @property
    def breakdown(self) -> Dict[str, float]:
        """Energy drawn so far per consumer of the pack [J]."""
        return {k: getattr(self._energy, k) for k in self.consumers}

    @property
    def percentage(self) -> float:
        """State of charge [%]."""
        initial = self.config.initial_percentage / 100.0 * self.capacity_j
        return max(0.0, initial - self.drawn) / self.capacity_j * 100.0

    @property
    def charge_ah(self) -> float:
        return self.percentage / 100.0 * self.config.capacity_ah

    @property
    def voltage(self) -> float:
        """Pack voltage [V], linear in the state of charge (module docstring)."""
        c = self.config
        p0 = c.percentage_at_empty_voltage
        return c.empty_voltage + max(self.percentage - p0, 0.0) / (100.0 - p0) * (c.full_voltage - c.empty_voltage)

    @property
    def current(self) -> float:
        """Discharge current [A] (negative: discharging, as sensor_msgs/BatteryState)."""
        return -self.power / max(self.voltage, 1e-6)


class BatteryModel:
    """Integrates the drain into the two packs, ``base`` and ``computer``; ``energy`` is the breakdown.

    Args:
        config: the constants.
    """

    def __init__(self, config: BatteryConfig) -> None:
        self.config = config
        self.energy = EnergyBreakdown()
        self.base = Pack(config.base_pack, self.energy, BASE_CONSUMERS)
        self.computer = Pack(config.computer_pack, self.energy, COMPUTER_CONSUMERS)
        self.cpu_seconds = 0.0    # CPU time charged so far [s]
        self.radio_bytes = 0      # radio traffic charged so far [bytes]
        self._work_rate = 0.0     # latest measured CPU + radio power [W]

    @property
    def packs(self) -> Tuple[Pack, Pack]:
        return self.base, self.computer

    @property
    def cpu_joules_per_cpu_second(self) -> float:
        """Energy per CPU-second of this machine charged [J]: full-load power over the capacity."""
        return self.config.cpu_full_load_power / self.config.cpu_capacity

    def motor_power(self, v: float, w: float, accel: float, alpha: float) -> float:
        """Electrical motor power [W] for speed v [m/s], yaw rate w [rad/s] and their derivatives."""
        c = self.config
        mech = (c.mass * GRAVITY * c.rolling_resistance * abs(v) + c.mass * abs(accel * v)
                + c.yaw_inertia * abs(alpha * w) + c.turn_resistance_power * abs(w) / math.pi)
        return mech / c.motor_efficiency

    def step(self, dt: float, v: float, w: float, accel: float, alpha: float) -> None:
        """Advance sim time by dt [s] with the base's motion over the step."""
        c = self.config
        motors = self.motor_power(v, w, accel, alpha)
        self.energy.base_idle += c.base_idle_power * dt
        self.energy.motors += motors * dt
        self.energy.laptop_idle += c.laptop_idle_power * dt
        if dt > 0:
            self.base.power = c.base_idle_power + motors
            self.computer.power = c.laptop_idle_power + self._work_rate

    def add_work(self, cpu_seconds: float, bytes_transferred: float, interval: float) -> None:
        """Account measured CPU time [s] and radio traffic [bytes] that happened over ``interval`` [s]."""
        c = self.config
        e_cpu = self.cpu_joules_per_cpu_second * max(cpu_seconds, 0.0)
        e_radio = c.radio_joules_per_byte * max(bytes_transferred, 0.0)
        self.energy.cpu += e_cpu
        self.energy.radio += e_radio
        self.cpu_seconds += max(cpu_seconds, 0.0)
        self.radio_bytes += int(max(bytes_transferred, 0))
        if interval > 0:
            self._work_rate = (e_cpu + e_radio) / interval
            self.computer.power = c.laptop_idle_power + self._work_rate


class CpuMeter:
    """CPU seconds used by a changing set of processes (psutil cpu_times deltas)."""

    needs_pids = True         # the caller keeps the set current with set_pids()
    problem = ''

    def __init__(self) -> None:
        import psutil
        self._psutil = psutil
        self._procs: Dict[int, object] = {}
        self._last: Dict[int, float] = {}
        self.dead: Set[int] = set()

    def set_pids(self, pids: Iterable[int]) -> None:
        pids = set(pids)
        for pid in list(self._procs):
            if pid not in pids:
                self._procs.pop(pid)
                self._last.pop(pid, None)
        for pid in pids - set(self._procs):
            try:
                proc = self._psutil.Process(pid)
                t = proc.cpu_times()
            except (self._psutil.NoSuchProcess, self._psutil.AccessDenied):
                self.dead.add(pid)
                continue
            self._procs[pid] = proc
            self._last[pid] = t.user + t.system

    @property
    def pids(self) -> Set[int]:
        return set(self._procs)

    def sample(self) -> float:
        """CPU seconds used since the previous sample by the tracked processes."""
        used = 0.0
        for pid, proc in list(self._procs.items()):
            try:
                t = proc.cpu_times()
            except (self._psutil.NoSuchProcess, self._psutil.AccessDenied):
                self._procs.pop(pid)
                self._last.pop(pid, None)
                self.dead.add(pid)
                continue
            total = t.user + t.system
            used += max(total - self._last[pid], 0.0)
            self._last[pid] = total
        return used


class CgroupCpuMeter:
    """CPU seconds used by the processes of a cgroup, read by ``reader`` (the ``~battery/cpu_usage`` plugin's,
    e.g. the testbed's CPU cap): exactly the robot's computer, exited processes included.

    A group that appears after the meter started is charged from its creation; one that is re-created (its
    usage restarts) from the new start. ``problem`` says why the last sample could not be read ('' if it was).
    """

    needs_pids = False

    def __init__(self, reader: CpuUsage) -> None:
        self._reader = reader
        self._last: Optional[float] = None
        self._missed_first = False

    @property
    def problem(self) -> str:
        return self._reader.problem

    def sample(self) -> float:
        """CPU seconds used since the previous sample (0 while the group cannot be read)."""
        used = self._reader.read()
        if used is None:
            self._missed_first = self._missed_first or self._last is None
            return 0.0
        prev, self._last = self._last, used
        if prev is None:
            return used if self._missed_first else 0.0
        return used - prev if used >= prev else used


def cpu_meter(cgroup: str, usage: Callable[[str], CpuUsage]) -> Union[CpuMeter, CgroupCpuMeter]:
    """The CPU meter for ``~battery/cpu_cgroup``: the cgroup's, read by ``usage(cgroup)`` (a bad name:
    ValueError), or ('') one over the robot's processes."""
    return CgroupCpuMeter(usage(cgroup)) if cgroup else CpuMeter()


class NetMeter:
    """Bytes sent + received on an interface ('' = every interface except loopback).

    psutil reads /proc/net/dev, which shows the network namespace of the calling process: run inside the
    robot's namespace (``ip netns exec robot``) it counts the robot's link (the testbed's TUN device).
    """

    def __init__(self, interface: str = '') -> None:
        import psutil
        self._psutil = psutil
        self.interface = interface
        self._last: Optional[int] = None

    def _total(self) -> int:
        counters = self._psutil.net_io_counters(pernic=True)
        if self.interface:
            c = counters.get(self.interface)
            return 0 if c is None else c.bytes_sent + c.bytes_recv
        return sum(c.bytes_sent + c.bytes_recv for name, c in counters.items() if name != 'lo')

    def sample(self) -> int:
        """Bytes moved since the previous sample."""
        total = self._total()
        prev, self._last = self._last, total
        return 0 if prev is None else max(total - prev, 0)
