"""Testbed configuration, condition traces and link-quality maps (ROS-free; errors name file and field)."""
from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from cnr_params import ConfigError, Section

from cnr_testbed.core import cpucap
from cnr_testbed.core.link import Conditions, check_changes

NAME_RE = re.compile(r'^[A-Za-z0-9_.-]{1,15}$')
CONDITION_KEYS = ('delay', 'jitter', 'loss', 'rate', 'queue', 'outage', 'reorder')


@dataclass
class RobotCpuConfig:
    """The robot's computer as a CPU-limited cgroup (``testbed.robot_cpu``)."""

    enabled: bool
    slowdown: float           # how many times slower a robot core is than a cloud (= this machine's) core
    period_us: int            # CFS enforcement period [us]

    @property
    def cpus(self) -> float:
        """The cap in CPUs' worth of this machine: one core slowed down ``slowdown`` times."""
        return 1.0 / self.slowdown


def robot_cpu_from(sec: Section) -> RobotCpuConfig:
    cfg = RobotCpuConfig(enabled=sec.boolean('enabled'), slowdown=sec.number('slowdown', positive=True),
                         period_us=sec.integer('period_us', minimum=cpucap.MIN_PERIOD_US,
                                               maximum=cpucap.MAX_PERIOD_US))
    try:
        cpucap.quota_us(cfg.cpus, cfg.period_us)
    except ValueError as exc:
        raise sec.error('period_us', str(exc)) from None
    return cfg


@dataclass
class TestbedConfig:
    name: str                 # instance name: control socket /run/cnr_testbed/<name>.sock
    robot_ns: str
    cloud_ns: str
    robot_address: str        # e.g. 10.77.0.1
    cloud_address: str
    prefix: int
    mtu: int
    robot_dev: str
    cloud_dev: str
    up: Conditions            # robot -> cloud
    down: Conditions          # cloud -> robot
    robot_cpu: RobotCpuConfig
    sysctl: Dict[str, int]    # per-namespace kernel settings (net.*) written in both namespaces at start
    sysctl_if_available: Dict[str, int]   # the same, skipped (with a note) where the kernel lacks the setting
    emulator_nice: int        # the link emulator's nice value (-20..19)


SYSCTL_RE = re.compile(r'^net(\.[a-z0-9_]+)+$')


def sysctl_from(sec: Section) -> Dict[str, int]:
    """``testbed.sysctl`` or ``testbed.sysctl_if_available``: network settings of the hosts' kernels (``net.*``,
    each namespace has its own), integers."""
    out = {}
    for key in sec.keys():
        if not SYSCTL_RE.match(key):
            raise sec.error(key, 'not a per-namespace network setting (net.<group>.<name>, e.g. '
                                 'net.ipv4.tcp_thin_linear_timeouts)')
        out[key] = sec.integer(key)
    return out


def _name(sec: Section, key: str) -> str:
    v = sec.string(key)
    if not NAME_RE.match(v):
        raise sec.error(key, f"'{v}' is not a valid name (letters, digits, _.-, at most 15)")
    return v


def conditions_from(sec: Section, base: Optional[Conditions] = None) -> Conditions:
    """Conditions from ``sec``: every one required, or (with ``base``) only those that change ``base``."""
    kw = {}
    for key in CONDITION_KEYS:
        if base is None or key in sec:
            if key in ('outage', 'reorder'):
                kw[key] = sec.boolean(key)
            elif key == 'queue':
                kw[key] = sec.integer(key, minimum=1)
            elif key == 'loss':
                kw[key] = sec.number(key, minimum=0.0, maximum=1.0)
            else:
                kw[key] = sec.number(key, nonnegative=True)
    unknown = [k for k in sec.keys() if k not in CONDITION_KEYS]
    if unknown:
        raise sec.error(unknown[0], f'unknown condition (expected: {", ".join(CONDITION_KEYS)})')
    return base.updated(**kw) if base is not None else Conditions(**kw).validate()


def load_testbed(path: str, overrides: Optional[Dict[str, str]] = None) -> TestbedConfig:
    doc = Section.from_file(path)
    t = doc.section('testbed')
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in t.data.items()}
    for key, value in (overrides or {}).items():      # dotted keys: name=tb1, robot.namespace=tb1r
        parts = key.split('.')
        node = data
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    t = Section(data, path, 'testbed')
    robot = t.section('robot')
    cloud = t.section('cloud')
    prefix = t.integer('prefix', minimum=8, maximum=30)
    addrs = []
    for side, sec in (('robot', robot), ('cloud', cloud)):
        try:
            addrs.append(str(ipaddress.IPv4Address(sec.string('address'))))
        except ipaddress.AddressValueError:
            raise sec.error('address', f"not an IPv4 address: {sec.raw('address')!r}") from None
    if addrs[0] == addrs[1]:
        raise cloud.error('address', 'must differ from the robot address')
    link = t.section('link')
    both = conditions_from(link.section('both'))
    cfg = TestbedConfig(name=_name(t, 'name'), robot_ns=_name(robot, 'namespace'),
                        cloud_ns=_name(cloud, 'namespace'), robot_address=addrs[0], cloud_address=addrs[1],
                        prefix=prefix, mtu=t.integer('mtu', minimum=576, maximum=65000),
                        robot_dev=_name(robot, 'device'), cloud_dev=_name(cloud, 'device'),
                        up=conditions_from(link.section('up', {}), both),
                        down=conditions_from(link.section('down', {}), both),
                        robot_cpu=robot_cpu_from(t.section('robot_cpu')),
                        sysctl=sysctl_from(t.section('sysctl')),
                        sysctl_if_available=sysctl_from(t.section('sysctl_if_available')),
                        emulator_nice=t.integer('emulator_nice', minimum=-20, maximum=19))
    if cfg.robot_ns == cfg.cloud_ns:
        raise cloud.error('namespace', 'must differ from the robot namespace')
    return cfg


# -- traces --------------------------------------------------------------------------------------
@dataclass
class TraceStep:
    time: float                     # s from the start of the trace
    direction: str                  # up, down, both
    changes: Dict[str, object]


def load_trace(path: str) -> List[TraceStep]:
    """A TSV trace: a header naming columns (``time`` [s], ``direction``, then any of the conditions), one
    row per change. Empty cells leave a condition unchanged. Times must not decrease."""
    try:
        with open(path) as f:
            lines = [l.rstrip('\n') for l in f if l.strip() and not l.lstrip().startswith('#')]
    except OSError as exc:
        raise ConfigError(path, 'file', str(exc)) from None
    if not lines:
        raise ConfigError(path, 'header', 'empty trace')
    header = [h.strip() for h in lines[0].split('\t')]
    if header[:2] != ['time', 'direction']:
        raise ConfigError(path, 'header', f"must start with 'time<TAB>direction', got {header[:2]}")
    for h in header[2:]:
        if h not in CONDITION_KEYS:
            raise ConfigError(path, 'header', f"unknown column '{h}' (expected: {', '.join(CONDITION_KEYS)})")
    steps, last = [], -1.0
    for no, line in enumerate(lines[1:], 2):
        cells = line.split('\t')
        where = f'line {no}'
        if len(cells) > len(header):
            raise ConfigError(path, where, f'{len(cells)} columns, header has {len(header)}')
        try:
            t = float(cells[0])
        except ValueError:
            raise ConfigError(path, f'{where}.time', f'not a number: {cells[0]!r}') from None
        if not t >= last:
            raise ConfigError(path, f'{where}.time', f'{t} is before the previous row ({last})')
        direction = cells[1].strip()
        if direction not in ('up', 'down', 'both'):
            raise ConfigError(path, f'{where}.direction', f"must be up, down or both, got {direction!r}")
        changes = {}
        for key, cell in zip(header[2:], cells[2:]):
            cell = cell.strip()
            if not cell:
                continue
            try:
                changes[key] = (cell.lower() in ('1', 'true', 'on', 'yes')) if key in ('outage', 'reorder') else \
                    (int(cell) if key == 'queue' else float(cell))
            except ValueError:
                raise ConfigError(path, f'{where}.{key}', f'not a number: {cell!r}') from None
        try:
            check_changes(changes)
        except ValueError as exc:
            raise ConfigError(path, where, str(exc)) from None
        steps.append(TraceStep(t, direction, changes))
        last = t
    return steps


# -- link-quality maps ----------------------------------------------------------------------------
@dataclass
class Region:
    name: str
    x_min: float
    x_max: float
    y_min: float
    y_max: float
    conditions: Conditions

    def contains(self, x: float, y: float) -> bool:
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max


@dataclass
class LinkMap:
    regions: List[Region]
    default: Conditions
    direction: str = 'both'      # which direction(s) of the link the map sets: up, down or both

    def conditions_at(self, x: float, y: float) -> Tuple[str, Conditions]:
        """The first region containing (x, y), else the default."""
        for r in self.regions:
            if r.contains(x, y):
                return r.name, r.conditions
        return 'default', self.default


def load_link_map(path: str) -> LinkMap:
    """``link_map: {direction, default: {conditions}, regions: [{name, x: [min, max], y: [min, max], <conditions>}]}``;
    a dead zone is a region with ``outage: true``; ``direction`` (up, down, both) is the direction the map sets
    (up: robot -> cloud only, the other direction keeps its conditions)."""
    doc = Section.from_file(path).section('link_map')
    default = conditions_from(doc.section('default'))
    regions = []
    for r in doc.sections('regions'):
        x = r.vector('x', 2)
        y = r.vector('y', 2)
        if not (x[0] < x[1] and y[0] < y[1]):
            raise r.error('x' if not x[0] < x[1] else 'y', 'expected [min, max] with min < max')
        cond = Section({k: v for k, v in r.data.items() if k not in ('name', 'x', 'y')}, r.source, r.prefix)
        regions.append(Region(r.string('name'), x[0], x[1], y[0], y[1],
                              conditions_from(cond, default)))
    return LinkMap(regions, default, doc.string('direction', choices=('up', 'down', 'both')))
