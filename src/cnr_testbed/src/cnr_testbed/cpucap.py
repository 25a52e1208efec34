"""The robot's computer as a CPU-limited cgroup (ROS-free; creating and joining need root).

    python3 -m cnr_testbed.cpucap create [--name N] [--cpus Q] [--period-us P]
    python3 -m cnr_testbed.cpucap run    [--name N] [--cpus Q] [--period-us P] -- CMD [ARGS...]
    python3 -m cnr_testbed.cpucap status [--name N] [--json]
    python3 -m cnr_testbed.cpucap top    [--name N] [--seconds S]
    python3 -m cnr_testbed.cpucap remove [--name N] [--kill]

``run`` creates the cgroup if it is missing (limit from the config or the options), moves itself into it and
execs CMD, so CMD and all its children are capped and CMD's exit status is the command's. Put it before
``ip netns exec`` (``cpucap run -- ip netns exec robot roslaunch ...``); after it works too (the cgroup
file system, which ``ip netns exec`` hides, is then reached through an ancestor process's root). Without a
usable cgroup (not root, no cpu controller) ``run`` prints one line and runs CMD uncapped.

Defaults: the name is ``cnr_robot_<testbed.name>``, the limit ``testbed.robot_cpu`` of config/testbed.yaml
(``--cpus`` is a fraction of one CPU: 0.25 = a quarter of a core). ``remove`` moves the processes still
inside to the parent cgroup (``--kill``: kills them) and deletes the group. ``top`` watches the group for S
seconds (default 20) and prints what each kind of process used (a ROS node by its name), in CPUs, beside the
limit and the share of CFS periods in which the group was throttled: what the robot's computer spends its
budget on.

Python::

    from cnr_testbed import cpucap
    cg = cpucap.CpuCgroup(cpucap.detect(), 'cnr_robot_cnr')
    cg.create(cpus=0.25, period_us=10000); cg.add(pid); cg.usage_seconds(); cg.throttling(); cg.remove()
    argv = cpucap.run_argv(['roslaunch', ...], 'cnr_robot_cnr')      # the command, capped
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

from cnr_params import ConfigError

from cnr_testbed.core import cpucap as core
from cnr_testbed.core.config import TestbedConfig, load_testbed
from cnr_testbed.core.cpucap import Layout, NoCgroup, Throttling

WS = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
CONFIG = os.path.join(WS, 'config', 'testbed.yaml')


def _read(path: str) -> str:
    with open(path) as f:
        return f.read()


def _write(path: str, text: str) -> None:
    with open(path, 'w') as f:
        f.write(text)


def _ancestors() -> List[int]:
    """This process and its ancestors, up to (not including) pid 1."""
    out, pid = [], os.getpid()
    while pid > 1 and len(out) < 64:
        out.append(pid)
        try:
            status = _read(f'/proc/{pid}/status')
        except OSError:
            break
        pid = next((int(line.split()[1]) for line in status.splitlines() if line.startswith('PPid:')), 0)
    return out


def detect() -> Layout:
    """The cgroup hierarchy with the cpu controller, as seen from here.

    ``ip netns exec`` gives its command a fresh /sys without the cgroup mounts; then an ancestor's view
    (``/proc/<pid>/root``, the mount namespace the command was started from) is used.

    Raises:
        NoCgroup: none found (the message says why).
    """
    reason = 'no cgroup file system visible'
    for pid in _ancestors():
        try:
            mounts = core.parse_mountinfo(_read(f'/proc/{pid}/mountinfo'))
        except OSError:
            continue
        if not any(m.fstype in ('cgroup', 'cgroup2') for m in mounts):
            continue
        prefix = '' if pid == os.getpid() else f'/proc/{pid}/root'
        unified = core.v2_mount(mounts)
        try:
            controllers = _read(f'{prefix}{unified}/cgroup.controllers') if unified else ''
        except OSError:
            controllers = ''
        try:
            layout = core.choose_layout(mounts, controllers, prefix)
        except NoCgroup as exc:
            reason = str(exc)
            continue
        if os.path.isdir(layout.cpu):
            return layout
        reason = f'{layout.cpu} is not reachable'
    raise NoCgroup(reason)


class CpuCgroup:
    """A named cgroup directly below the root of the cpu (and, v1, cpuacct) hierarchy.

    Args:
        layout: from :func:`detect`.
        name: one directory level (:func:`cnr_testbed.core.cpucap.check_name`).
    """

    def __init__(self, layout: Layout, name: str) -> None:
        self.layout = layout
        self.name = core.check_name(name)
        self.cpu_dir = os.path.join(layout.cpu, name)
        self.acct_dir = os.path.join(layout.acct, name) if layout.acct else None
        self.dirs = [os.path.join(h, name) for h in layout.hierarchies()]

    def exists(self) -> bool:
        return os.path.isdir(self.cpu_dir)

    def create(self, cpus: Optional[float], period_us: int) -> None:
        """Create the group (all its hierarchies; an existing one is kept) and set its limit.

        Raises:
            ValueError: the kernel would refuse the limit (checked before anything is created).
            OSError: not permitted (not root) or the kernel refused.
        """
        files = core.limit_files(self.layout.version, cpus, period_us)
        if self.layout.version == 2:
            control = os.path.join(self.layout.cpu, 'cgroup.subtree_control')
            if 'cpu' not in _read(control).split():
                _write(control, '+cpu')
        for d in self.dirs:
            os.makedirs(d, exist_ok=True)
        for name, text in files:
            _write(os.path.join(self.cpu_dir, name), text)

    def set_limit(self, cpus: Optional[float], period_us: int) -> None:
        for name, text in core.limit_files(self.layout.version, cpus, period_us):
            _write(os.path.join(self.cpu_dir, name), text)

    def limit(self) -> Tuple[Optional[float], int]:
        """(cpus or None when unlimited, period [us])."""
        names = ('cpu.cfs_period_us', 'cpu.cfs_quota_us') if self.layout.version == 1 else ('cpu.max',)
        return core.parse_limit(self.layout.version, {n: _read(os.path.join(self.cpu_dir, n)) for n in names})

    def add(self, pid: int) -> None:
        """Move the process ``pid`` (all its threads) into the group."""
        for d in self.dirs:
            _write(os.path.join(d, 'cgroup.procs'), str(pid))

    def pids(self) -> List[int]:
        out = set()
        for d in self.dirs:
            try:
                out.update(core.parse_pids(_read(os.path.join(d, 'cgroup.procs'))))
            except FileNotFoundError:
                continue
        return sorted(out)

    def times_by_pid(self) -> Dict[int, Tuple[str, float]]:
        """pid -> (label as in :meth:`by_process`, CPU time [s] so far) of each process now in the group."""
        import psutil
        out: Dict[int, Tuple[str, float]] = {}
        for pid in self.pids():
            try:
                proc = psutil.Process(pid)
                label = core.process_label(proc.cmdline()) or proc.name()
                t = proc.cpu_times()
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                continue
            out[pid] = (label, t.user + t.system)
        return out

    def by_process(self) -> Dict[str, float]:
        """CPU time [s] used so far by each kind of process now in the group (:func:`core.process_label`: a ROS
        node's name, else the program), largest first. Processes that have already exited are not counted (their
        time is in :meth:`usage_seconds`)."""
        totals: Dict[str, float] = {}
        for label, t in self.times_by_pid().values():
            totals[label] = totals.get(label, 0.0) + t
        return dict(sorted(totals.items(), key=lambda kv: -kv[1]))

    def usage_seconds(self) -> float:
        """CPU time [s] used by the group's processes since it was created (exited ones included).

        Raises:
            NoCgroup: v1 without a cpuacct hierarchy.
        """
        if self.acct_dir is None:
            raise NoCgroup('no cpuacct hierarchy mounted: CPU usage of a cgroup is not available')
        f = 'cpuacct.usage' if self.layout.version == 1 else 'cpu.stat'
        return core.usage_seconds(self.layout.version, _read(os.path.join(self.acct_dir, f)))

    def throttling(self) -> Throttling:
        return core.throttling(self.layout.version, _read(os.path.join(self.cpu_dir, 'cpu.stat')))

    def remove(self, kill: bool = False, timeout: float = 5.0) -> List[int]:
        """Delete the group; processes still inside go to the parent group (``kill``: are killed first).

        Returns the pids found inside. Raises OSError if the group cannot be emptied within ``timeout`` s.
        """
        found = self.pids()
        deadline = time.monotonic() + timeout
        while True:
            left = self.pids()
            for pid in left:
                try:
                    if kill:
                        os.kill(pid, signal.SIGKILL)
                    else:
                        for d in self.dirs:
                            _write(os.path.join(os.path.dirname(d), 'cgroup.procs'), str(pid))
                except (ProcessLookupError, FileNotFoundError):   # exited meanwhile (ESRCH)
                    continue
            try:
                for d in reversed(self.dirs):
                    if os.path.isdir(d):
                        os.rmdir(d)
                return found
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def status(self) -> Dict:
        cpus, period = self.limit()
        st = dict(name=self.name, version=self.layout.version, dirs=self.dirs, cpus=cpus, period_us=period,
                  pids=self.pids())
        try:
            st['usage_seconds'] = self.usage_seconds()
        except NoCgroup:
            st['usage_seconds'] = None
        t = self.throttling()
        st.update(periods=t.periods, throttled=t.throttled, throttled_seconds=t.throttled_seconds)
        return st


class UsageReader:
    """CPU seconds used by a cgroup, for a long-running meter (the simulator's battery).

    Keeps a descriptor of the group's accounting directory, so it keeps working when the ancestor whose
    view of /sys it was found through exits; re-finds the group when it is removed and created again.
    """

    def __init__(self, name: str) -> None:
        self.name = core.check_name(name)
        self._fd: Optional[int] = None
        self._version = 1
        self.problem = ''

    def _open(self) -> None:
        layout = detect()
        cg = CpuCgroup(layout, self.name)
        if cg.acct_dir is None:
            raise NoCgroup('no cpuacct hierarchy mounted')
        self._fd = os.open(cg.acct_dir, os.O_RDONLY | os.O_DIRECTORY)
        self._version = layout.version

    def read(self) -> Optional[float]:
        """Seconds of CPU used by the group so far, or None when it cannot be read (see ``problem``)."""
        try:
            if self._fd is None:
                self._open()
            fd = os.open('cpuacct.usage' if self._version == 1 else 'cpu.stat', os.O_RDONLY, dir_fd=self._fd)
            try:
                text = os.read(fd, 4096).decode()
            finally:
                os.close(fd)
            self.problem = ''
            return core.usage_seconds(self._version, text)
        except (OSError, NoCgroup, ValueError) as exc:
            self.close()
            self.problem = f'cgroup {self.name}: {exc}'
            return None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def run_argv(argv: Sequence[str], name: str, config: Optional[str] = None) -> List[str]:
    """``argv`` prefixed so that it runs inside the cgroup ``name`` (created from the config if missing)."""
    return [sys.executable, '-m', 'cnr_testbed.cpucap', 'run', '--name', name,
            *(['--config', config] if config else []), '--', *argv]


# -- command line ----------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog='cnr_testbed.cpucap', description=__doc__.split('\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split('Python::')[0])
    ap.add_argument('--config', default=CONFIG, help='testbed YAML (testbed.name, testbed.robot_cpu)')
    sub = ap.add_subparsers(dest='cmd', required=True)
    for cmd in ('create', 'run', 'status', 'top', 'remove'):
        p = sub.add_parser(cmd)
        p.add_argument('--config', default=argparse.SUPPRESS)
        p.add_argument('--name', help='cgroup name (default cnr_robot_<testbed.name>)')
        if cmd in ('create', 'run'):
            p.add_argument('--cpus', type=float, help='limit in CPUs, a fraction of one (default 1/slowdown)')
            p.add_argument('--period-us', type=int, help='CFS period [us] (default robot_cpu.period_us)')
        if cmd == 'run':
            p.add_argument('command', nargs=argparse.REMAINDER, help='-- CMD [ARGS...]')
        if cmd == 'status':
            p.add_argument('--json', action='store_true')
        if cmd == 'top':
            p.add_argument('--seconds', type=float, default=20.0, help='window [s] (default 20)')
        if cmd == 'remove':
            p.add_argument('--kill', action='store_true', help='kill the processes still inside')
    return ap


def _say(text: str) -> None:
    print(f'cpucap: {text}', file=sys.stderr, flush=True)


def _exec(command: List[str]) -> int:
    try:
        os.execvp(command[0], command)
    except OSError as exc:
        _say(f'{command[0]}: {exc.strerror}')
        return 127 if isinstance(exc, FileNotFoundError) else 126
    return 0  # not reached


def _join(args: argparse.Namespace, cfg: TestbedConfig, name: str) -> None:
    """Create-if-missing and join the group ``name``; raises NoCgroup/OSError/ValueError."""
    if os.geteuid() != 0:
        raise NoCgroup('not root')
    cg = CpuCgroup(detect(), name)
    if not cg.exists():
        cg.create(args.cpus if args.cpus is not None else cfg.robot_cpu.cpus,
                  args.period_us if args.period_us is not None else cfg.robot_cpu.period_us)
    cg.add(os.getpid())


def _top(cg: 'CpuCgroup', name: str, seconds: float) -> int:
    if not seconds > 0:
        _say(f'--seconds must be > 0, got {seconds:g}')
        return 2
    if not cg.exists():
        _say(f'cgroup {name}: absent (is the testbed up?)')
        return 1
    cpus, _period = cg.limit()
    before, th0, t0 = cg.times_by_pid(), cg.throttling(), time.monotonic()
    u0 = cg.usage_seconds() if cg.acct_dir is not None else None
    _say(f'watching cgroup {name} for {seconds:g} s ...')
    time.sleep(seconds)
    after, th1, dt = cg.times_by_pid(), cg.throttling(), time.monotonic() - t0
    u1 = cg.usage_seconds() if cg.acct_dir is not None else None
    shares = core.cpu_shares(before, after, dt)
    width = max([len(k) for k in shares] + [7])
    for label, share in shares.items():
        print(f'{label:<{width}}  {share:.3f}')
    total = sum(shares.values())
    print(f'{"total":<{width}}  {total:.3f} CPU (processes alive at the end)')
    if u0 is not None and u1 is not None:
        print(f'{"cgroup":<{width}}  {(u1 - u0) / dt:.3f} CPU (exited processes included)')
    lim = 'unlimited' if cpus is None else f'{cpus:.3f} CPU'
    periods, throttled = th1.periods - th0.periods, th1.throttled - th0.throttled
    print(f'limit {lim}; throttled in {throttled} of {periods} periods over {dt:.1f} s')
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parser().parse_args(argv)
    try:
        cfg = load_testbed(args.config)
    except ConfigError as exc:
        _say(str(exc))
        return 2
    name = args.name or core.default_name(cfg.name)
    if args.cmd == 'run':
        command = args.command[1:] if args.command[:1] == ['--'] else args.command
        if not command:
            _say('run needs a command: run [options] -- CMD [ARGS...]')
            return 2
        if not cfg.robot_cpu.enabled and args.cpus is None:
            _say(f'robot CPU cap disabled ({args.config}: testbed.robot_cpu.enabled: false): running without it')
        else:
            try:
                _join(args, cfg, name)
            except (NoCgroup, OSError, ValueError) as exc:
                _say(f'no cpu cgroup available ({exc}): running without the robot CPU cap')
        return _exec(command)
    try:
        if args.cmd == 'create':
            cpus = args.cpus if args.cpus is not None else cfg.robot_cpu.cpus
            period = args.period_us if args.period_us is not None else cfg.robot_cpu.period_us
            core.quota_us(cpus, period)
            try:
                if os.geteuid() != 0:
                    raise NoCgroup('not root')
                cg = CpuCgroup(detect(), name)
                cg.create(cpus, period)
            except (NoCgroup, OSError) as exc:
                _say(f'no cpu cgroup available ({exc}): running without the robot CPU cap')
                return 0
            print(f'cgroup {name}: {cpus:.4g} CPU per {period} us (cgroup v{cg.layout.version}, {cg.cpu_dir})')
        elif args.cmd == 'status':
            cg = CpuCgroup(detect(), name)
            if not cg.exists():
                print(json.dumps(None) if args.json else f'cgroup {name}: absent')
                return 0
            st = cg.status()
            if args.json:
                print(json.dumps(st, indent=1))
            else:
                lim = 'unlimited' if st['cpus'] is None else f"{st['cpus']:.4g} CPU per {st['period_us']} us"
                use = 'n/a' if st['usage_seconds'] is None else f"{st['usage_seconds']:.3f} s"
                print(f"cgroup {name} (v{st['version']}): {lim}; used {use}; throttled in {st['throttled']} of "
                      f"{st['periods']} periods ({st['throttled_seconds']:.3f} s); pids {st['pids']}")
        elif args.cmd == 'top':
            return _top(CpuCgroup(detect(), name), name, args.seconds)
        elif args.cmd == 'remove':
            try:
                cg = CpuCgroup(detect(), name)
            except NoCgroup:
                return 0
            if cg.exists():
                left = cg.remove(kill=args.kill)
                print(f'cgroup {name}: removed' + (f" ({'killed' if args.kill else 'moved out'} pids {left})"
                                                   if left else ''))
    except NoCgroup as exc:
        _say(f'no cpu cgroup available ({exc})')
        return 1
    except (OSError, ValueError) as exc:
        _say(str(exc))
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
