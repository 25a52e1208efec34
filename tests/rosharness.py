"""rostest-style helpers for pytest: a rosmaster on a free port, launched nodes, waiting on conditions.

Like ``rostest_parent.py`` the master gets an OS-chosen port (never 11311). Every process
started here runs in its own process group and is stopped (SIGINT, then SIGKILL) on teardown.
"""
from __future__ import annotations

import os
import socket
import subprocess
import time
import xmlrpc.client
from typing import Callable, Dict, List, Optional, Sequence, TypeVar

from cnr_testbed.rosside import stop_process

T = TypeVar('T')
WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def wait_for(condition: Callable[[], T], timeout: float, what: str, interval: float = 0.05) -> T:
    """Poll ``condition`` until it returns a truthy value; fail with ``what`` after ``timeout`` wall seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout:.1f} s waiting for {what}')
        time.sleep(interval)


class Proc:
    """A child process in its own process group, stopped like roslaunch stops nodes."""

    def __init__(self, args: Sequence[str], env: Optional[Dict[str, str]] = None, log_name: str = 'proc') -> None:
        self.args = list(args)
        log_dir = os.path.join(WS, 'build', 'test_logs')
        os.makedirs(log_dir, exist_ok=True)
        self.log_path = os.path.join(log_dir, f'{log_name}-{os.getpid()}-{time.monotonic_ns()}.log')
        self._log = open(self.log_path, 'wb')
        self.popen = subprocess.Popen(self.args, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                                      start_new_session=True)

    def alive(self) -> bool:
        return self.popen.poll() is None

    def output(self) -> str:
        self._log.flush()
        with open(self.log_path, 'r', errors='replace') as f:
            return f.read()

    def stop(self, timeout: float = 10.0) -> Optional[int]:
        stop_process(self.popen, timeout)
        self._log.close()
        return self.popen.returncode


class RosMaster:
    """A rosmaster on a free port with ``/use_sim_time`` set as asked."""

    def __init__(self, use_sim_time: bool = True) -> None:
        self.port = free_port()
        self.uri = f'http://127.0.0.1:{self.port}/'
        self.env = dict(os.environ, ROS_MASTER_URI=self.uri, ROS_IP='127.0.0.1')
        self.env.pop('ROS_HOSTNAME', None)
        self.proc = Proc(['rosmaster', '--core', '-p', str(self.port)], env=self.env, log_name='rosmaster')
        self.proxy = xmlrpc.client.ServerProxy(self.uri)
        wait_for(self._up, 20.0, f'rosmaster on port {self.port}')
        self.proxy.setParam('/pytest', '/use_sim_time', use_sim_time)
        self.children: List[Proc] = []

    def _up(self) -> bool:
        try:
            return self.proxy.getSystemState('/pytest')[0] == 1
        except OSError:
            return False

    def run(self, args: Sequence[str], log_name: str = 'node') -> Proc:
        """Start a command (rosrun, roslaunch, a script) against this master; stopped at teardown."""
        proc = Proc(args, env=self.env, log_name=log_name)
        self.children.append(proc)
        return proc

    def roslaunch(self, package: str, launch_file: str, *args: str) -> Proc:
        return self.run(['roslaunch', package, launch_file, *args], log_name=launch_file)   # master is up already

    def node_names(self) -> List[str]:
        state = self.proxy.getSystemState('/pytest')[2]
        names = set()
        for group in state:
            for _, nodes in group:
                names.update(nodes)
        return sorted(names)

    def stop(self) -> None:
        for proc in reversed(self.children):
            proc.stop()
        self.children.clear()
        self.proc.stop()
