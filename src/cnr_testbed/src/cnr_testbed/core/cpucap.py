"""The robot's computer as a CPU-limited cgroup: the pure part (no file system access, no ROS).

Which hierarchy holds the ``cpu`` controller (cgroup v1, ``cpuacct`` co-mounted or separate, or cgroup v2),
the CFS bandwidth limit as the kernel files spell it, and the parsing of the usage and throttling statistics.
:mod:`cnr_testbed.cpucap` does the reading and writing.

CFS bandwidth control gives a group ``quota`` microseconds of CPU time per ``period`` microseconds, summed
over all CPUs (``cpus = quota / period`` CPUs' worth). The kernel refuses a quota below 1 ms and a period
outside 1 ms .. 1 s (kernel/sched/core.c, ``min_cfs_quota_period``, ``max_cfs_quota_period``), so a small
share of a CPU needs a period of at least ``1 ms / cpus``.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

MIN_QUOTA_US = 1000            # kernel minimum of cpu.cfs_quota_us / the quota of cpu.max
MIN_PERIOD_US = 1000
MAX_PERIOD_US = 1000000
NAME_RE = re.compile(r'^[A-Za-z0-9_.-]{1,64}$')


class NoCgroup(RuntimeError):
    """No usable cpu cgroup here; the message says why in a few words."""


# -- mounts ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mount:
    """One line of /proc/<pid>/mountinfo (the fields we need)."""

    root: str                        # the mounted directory inside its file system
    point: str                       # where it is mounted
    fstype: str
    super_options: Tuple[str, ...]   # for a v1 cgroup: its controllers, e.g. ('rw', 'cpu', 'cpuacct')


def _unescape(field: str) -> str:
    """mountinfo escapes space, tab, newline and backslash as octal (\\040 ...)."""
    return re.sub(r'\\([0-7]{3})', lambda m: chr(int(m.group(1), 8)), field)


def parse_mountinfo(text: str) -> List[Mount]:
    """The mounts of a /proc/<pid>/mountinfo text (proc(5)); malformed lines are skipped."""
    out = []
    for line in text.splitlines():
        left, sep, right = line.partition(' - ')
        if not sep:
            continue
        a, b = left.split(), right.split()
        if len(a) < 5 or len(b) < 3:
            continue
        out.append(Mount(_unescape(a[3]), _unescape(a[4]), b[0], tuple(b[2].split(','))))
    return out


@dataclass(frozen=True)
class Layout:
    """Where a cgroup's files live.

    Attributes:
        version: 1 or 2.
        cpu: directory of the hierarchy with the ``cpu`` controller (limits, throttling statistics).
        acct: directory of the hierarchy with the CPU usage: v1 the ``cpuacct`` hierarchy (the same as ``cpu``
            when co-mounted, e.g. /sys/fs/cgroup/cpu,cpuacct), v2 the same as ``cpu``; None when there is none.
    """

    version: int
    cpu: str
    acct: Optional[str]

    def hierarchies(self) -> List[str]:
        """The distinct hierarchy directories a process has to join."""
        return [self.cpu] + ([self.acct] if self.acct and self.acct != self.cpu else [])


def v1_hierarchy(mounts: Sequence[Mount], controller: str) -> Optional[str]:
    """Mount point of the cgroup v1 hierarchy carrying ``controller`` (the first one)."""
    for m in mounts:
        if m.fstype == 'cgroup' and controller in m.super_options:
            return m.point
    return None


def v2_mount(mounts: Sequence[Mount]) -> Optional[str]:
    """Mount point of the cgroup v2 (unified) hierarchy, if any."""
    for m in mounts:
        if m.fstype == 'cgroup2':
            return m.point
    return None


def choose_layout(mounts: Sequence[Mount], v2_controllers: str = '', prefix: str = '') -> Layout:
    """The hierarchy to use: v1 ``cpu`` if mounted (the kernel then keeps ``cpu`` out of v2), else v2 if
    ``cpu`` is among its ``cgroup.controllers`` (the text of that file, given by the caller).

    Args:
        mounts: from :func:`parse_mountinfo`.
        v2_controllers: contents of the v2 root's cgroup.controllers ('' when there is no v2 mount).
        prefix: prepended to mount points (to reach another mount namespace's view: /proc/<pid>/root).

    Raises:
        NoCgroup: neither is available.
    """
    cpu = v1_hierarchy(mounts, 'cpu')
    if cpu is not None:
        acct = v1_hierarchy(mounts, 'cpuacct')
        return Layout(1, prefix + cpu, prefix + acct if acct is not None else None)
    unified = v2_mount(mounts)
    if unified is not None and 'cpu' in v2_controllers.split():
        return Layout(2, prefix + unified, prefix + unified)
    if unified is not None:
        raise NoCgroup(f'cgroup v2 at {unified} has no cpu controller and no cgroup v1 cpu hierarchy is mounted')
    raise NoCgroup('no cgroup v1 cpu hierarchy and no cgroup v2 mounted')


def check_name(name: str) -> str:
    """A cgroup name: one directory level of letters, digits, ``_ . -`` (at most 64)."""
    if not NAME_RE.match(name) or name in ('.', '..'):
        raise ValueError(f"'{name}' is not a valid cgroup name (letters, digits, _.-, at most 64)")
    return name


def default_name(testbed_name: str) -> str:
    """The robot's cgroup of a testbed instance."""
    return check_name(f'cnr_robot_{testbed_name}')


# -- limits ----------------------------------------------------------------------------------------
def quota_us(cpus: float, period_us: int) -> int:
    """The quota [us] giving ``cpus`` CPUs' worth of time per ``period_us``.

    Raises:
        ValueError: the kernel would refuse it (period outside 1 ms .. 1 s, quota below 1 ms).
    """
    if not (isinstance(period_us, int) and MIN_PERIOD_US <= period_us <= MAX_PERIOD_US):
        raise ValueError(f'period must be {MIN_PERIOD_US}..{MAX_PERIOD_US} us, got {period_us}')
    if not (math.isfinite(cpus) and cpus > 0):
        raise ValueError(f'cpus must be > 0, got {cpus}')
    quota = int(round(cpus * period_us))
    if quota < MIN_QUOTA_US:
        raise ValueError(f'quota {cpus:g} x {period_us} us = {quota} us is below the kernel minimum of '
                         f'{MIN_QUOTA_US} us: use a period of at least {shortest_period_us(cpus)} us')
    return quota


def shortest_period_us(cpus: float) -> int:
    """The shortest period the kernel accepts for ``cpus`` CPUs' worth (quota >= 1 ms)."""
    return max(MIN_PERIOD_US, int(math.ceil(MIN_QUOTA_US / cpus - 1e-9)))


def limit_files(version: int, cpus: Optional[float], period_us: int) -> List[Tuple[str, str]]:
    """(file, contents) to write, in order, for a limit of ``cpus`` CPUs per ``period_us`` (None: no limit)."""
    quota = quota_us(cpus, period_us) if cpus is not None else None
    if version == 1:
        return [('cpu.cfs_period_us', str(period_us)), ('cpu.cfs_quota_us', str(quota if quota else -1))]
    if version == 2:
        return [('cpu.max', f"{quota if quota else 'max'} {period_us}")]
    raise ValueError(f'unknown cgroup version {version}')


def parse_limit(version: int, files: Dict[str, str]) -> Tuple[Optional[float], int]:
    """(cpus or None when unlimited, period [us]) from the limit files' contents (as :func:`limit_files`)."""
    if version == 1:
        period = int(files['cpu.cfs_period_us'].strip())
        quota = int(files['cpu.cfs_quota_us'].strip())
    else:
        q, p = files['cpu.max'].split()
        period, quota = int(p), (-1 if q == 'max' else int(q))
    return (None if quota < 0 else quota / period), period


# -- statistics --------------------------------------------------------------------------------------
def parse_flat_keyed(text: str) -> Dict[str, int]:
    """A ``key value`` per line file (cpu.stat); lines that are not two fields with an integer are skipped."""
    out = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 2:
            try:
                out[parts[0]] = int(parts[1])
            except ValueError:
                continue
    return out


def usage_seconds(version: int, text: str) -> float:
    """CPU time [s] used by the group: v1 from cpuacct.usage (ns), v2 from cpu.stat (``usage_usec``)."""
    if version == 1:
        return int(text.strip()) / 1e9
    stat = parse_flat_keyed(text)
    if 'usage_usec' not in stat:
        raise ValueError('cpu.stat has no usage_usec')
    return stat['usage_usec'] / 1e6


@dataclass(frozen=True)
class Throttling:
    """CFS bandwidth statistics of a group."""

    periods: int              # enforcement periods in which the group was runnable
    throttled: int            # of which it ran out of quota
    throttled_seconds: float  # total time its threads waited for the next period

    @property
    def throttled_fraction(self) -> float:
        return self.throttled / self.periods if self.periods else 0.0


def throttling(version: int, cpu_stat: str) -> Throttling:
    """From cpu.stat: v1 ``throttled_time`` is in ns, v2 ``throttled_usec`` in us."""
    s = parse_flat_keyed(cpu_stat)
    waited = s.get('throttled_time', 0) / 1e9 if version == 1 else s.get('throttled_usec', 0) / 1e6
    return Throttling(s.get('nr_periods', 0), s.get('nr_throttled', 0), waited)


def parse_pids(text: str) -> List[int]:
    """The pids of a cgroup.procs text."""
    return [int(x) for x in text.split()]


def process_label(cmdline: List[str]) -> str:
    """What a process of the robot is, for a CPU breakdown: a ROS node's name (``__name:=``), else the program
    (the script a Python interpreter runs, e.g. ``rosmaster``, ``roslaunch``), '' for an empty command line."""
    for arg in cmdline:
        if arg.startswith('__name:='):
            return arg.split(':=', 1)[1]
    args = [a for a in cmdline if a and not a.startswith('-')]
    if not args:
        return ''
    prog = os.path.basename(args[0])
    if prog.startswith('python') and len(args) > 1:
        prog = os.path.basename(args[1])
    return prog


def cpu_shares(before: Dict[int, Tuple[str, float]], after: Dict[int, Tuple[str, float]],
               seconds: float) -> Dict[str, float]:
    """CPU used per kind of process over a window, in CPUs (CPU seconds per second), largest first.

    Args:
        before, after: pid -> (label, CPU time [s]) at the window's start and end. A process only in ``after``
            started in the window: all its time counts; one only in ``before`` exited: its last part is lost
            (the cgroup's own usage has it).
        seconds: the window's length.
    """
    if not seconds > 0:
        raise ValueError(f'the window must be > 0 s, got {seconds}')
    shares: Dict[str, float] = {}
    for pid, (label, t1) in after.items():
        t0 = before[pid][1] if pid in before and before[pid][0] == label else 0.0
        shares[label] = shares.get(label, 0.0) + max(0.0, t1 - t0) / seconds
    return dict(sorted(shares.items(), key=lambda kv: -kv[1]))
