"""Python API of the testbed (used by the benchmarks and tests).

    from cnr_testbed.api import Testbed
    with Testbed('config/testbed.yaml') as tb:          # up() ... down()
        tb.set('both', delay=25.0)                       # one-way ms per direction: +50 ms RTT
        tb.exec_in('robot', ['ping', '-c', '3', tb.cloud_address])
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from typing import Dict, List, Optional, Sequence

from cnr_testbed import netns
from cnr_testbed.core import cpucap as cpucap_core
from cnr_testbed.core.config import TestbedConfig, load_testbed
from cnr_testbed.emulator import cleanup, pid_path, socket_path


class TestbedError(RuntimeError):
    pass


def request(name: str, req: Dict, timeout: float = 5.0) -> Dict:
    """One JSON request to a running emulator's control socket."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(socket_path(name))
        s.sendall((json.dumps(req) + '\n').encode())
        data = b''
        while not data.endswith(b'\n'):
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    return json.loads(data.decode())


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs; reaps it if it is this process's exited child (a zombie would count as alive)."""
    try:
        if os.waitpid(pid, os.WNOHANG)[0] == pid:
            return False
    except ChildProcessError:
        pass
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False


class Testbed:
    """Robot and cloud namespaces joined by the link emulator.

    Args:
        config: path of the testbed YAML (``config/testbed.yaml``).
        overrides: dotted keys overriding ``testbed.*`` (e.g. ``{'name': 'tb1', 'robot.namespace': 'tb1r'}``).
    """

    def __init__(self, config: str, overrides: Optional[Dict[str, str]] = None) -> None:
        self.config_path = os.path.abspath(config)
        self.overrides = dict(overrides or {})
        self.cfg: TestbedConfig = load_testbed(self.config_path, self.overrides)

    @property
    def robot_address(self) -> str:
        return self.cfg.robot_address

    @property
    def cloud_address(self) -> str:
        return self.cfg.cloud_address

    @property
    def robot_cgroup(self) -> str:
        """Name of the robot's CPU-capped cgroup (:mod:`cnr_testbed.cpucap`)."""
        return cpucap_core.default_name(self.cfg.name)

    def namespace(self, side: str) -> str:
        if side not in ('robot', 'cloud'):
            raise TestbedError(f"unknown side {side!r} (robot or cloud)")
        return self.cfg.robot_ns if side == 'robot' else self.cfg.cloud_ns

    def supervisor_pid(self) -> Optional[int]:
        try:
            pid = int(open(pid_path(self.cfg.name)).read().strip())
        except (FileNotFoundError, ValueError):
            return None
        return pid if _alive(pid) else None

    def running(self) -> bool:
        try:
            return request(self.cfg.name, {'cmd': 'status'}, 1.0).get('ok', False)
        except OSError:
            return False

    def up(self, timeout: float = 15.0) -> Dict:
        if os.geteuid() != 0:
            raise TestbedError('needs root (network namespaces and TUN devices): run as root or with sudo')
        if self.running():
            raise TestbedError(f"testbed '{self.cfg.name}' is already up (testbed.sh down first)")
        self._clear_stale()
        existing = set(netns.namespaces())
        for ns in (self.cfg.robot_ns, self.cfg.cloud_ns):
            if ns in existing:
                raise TestbedError(f"network namespace '{ns}' already exists and is not ours; choose another "
                                   f"name in the config or remove it (ip netns delete {ns})")
        created = []
        try:
            for ns in (self.cfg.robot_ns, self.cfg.cloud_ns):
                netns.add_namespace(ns)
                created.append(ns)
                for key, value in self.cfg.sysctl.items():
                    netns.set_sysctl(ns, key, value)
                for key, value in self.cfg.sysctl_if_available.items():
                    if netns.has_sysctl(key):
                        netns.set_sysctl(ns, key, value)
                    elif ns == self.cfg.robot_ns:
                        print(f'testbed: this kernel has no {key}: left at its default', file=sys.stderr)
            args = [sys.executable, '-m', 'cnr_testbed.emulator', self.config_path]
            for k, v in self.overrides.items():
                args += ['--set', f'{k}={v}']
            log = open(os.path.join('/tmp', f'cnr_testbed-{self.cfg.name}.log'), 'ab')
            proc = subprocess.Popen(args, stdout=log, stderr=log, stdin=subprocess.DEVNULL, start_new_session=True)
            deadline = time.monotonic() + timeout
            while not self.running():
                if proc.poll() is not None:
                    raise TestbedError(f'the link emulator exited (see /tmp/cnr_testbed-{self.cfg.name}.log)')
                if time.monotonic() > deadline:
                    raise TestbedError('the link emulator did not come up')
                time.sleep(0.05)
        except Exception:
            self.down()
            for ns in created:
                netns.delete_namespace(ns)
            raise
        return self.status()

    def _clear_stale(self) -> None:
        """Leftovers of a crashed run (pid file of a dead supervisor, stale socket)."""
        if self.supervisor_pid() is None and os.path.exists(pid_path(self.cfg.name)):
            cleanup(self.cfg)

    def down(self, timeout: float = 10.0) -> None:
        pid = self.supervisor_pid()
        if pid is not None:
            os.kill(pid, signal.SIGTERM)
            deadline = time.monotonic() + timeout
            while _alive(pid) and time.monotonic() < deadline:
                time.sleep(0.05)
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        cleanup(self.cfg)
        self.remove_robot_cgroup()

    def remove_robot_cgroup(self) -> None:
        """Delete the robot's CPU cgroup if present (processes still inside move to the parent group)."""
        from cnr_testbed import cpucap
        try:
            cg = cpucap.CpuCgroup(cpucap.detect(), self.robot_cgroup)
            if cg.exists():
                cg.remove()
        except cpucap.NoCgroup:
            pass
        except OSError as exc:
            print(f'testbed: cannot remove the cgroup {self.robot_cgroup}: {exc}', file=sys.stderr)

    def status(self) -> Dict:
        try:
            reply = request(self.cfg.name, {'cmd': 'status'})
        except OSError:
            present = [ns for ns in (self.cfg.robot_ns, self.cfg.cloud_ns) if ns in netns.namespaces()]
            return dict(running=False, namespaces=present)
        return dict(running=True, **reply['status'])

    def set(self, direction: str = 'both', **conditions) -> Dict:
        reply = request(self.cfg.name, {'cmd': 'set', 'dir': direction, 'conditions': conditions})
        if not reply.get('ok'):
            raise TestbedError(reply.get('error', 'set failed'))
        return reply['status']

    def exec_in(self, side: str, argv: Sequence[str], **kw) -> subprocess.CompletedProcess:
        return subprocess.run(['ip', 'netns', 'exec', self.namespace(side), *argv], **kw)

    def popen_in(self, side: str, argv: Sequence[str], **kw) -> subprocess.Popen:
        return subprocess.Popen(['ip', 'netns', 'exec', self.namespace(side), *argv], **kw)

    def __enter__(self) -> 'Testbed':
        self.up()
        return self

    def __exit__(self, *exc) -> None:
        self.down()
