"""A rosmaster (or roscore) on a free port, waited for until it answers, and the processes run against it."""
from __future__ import annotations

import os
import sys
import tempfile
import time
import xmlrpc.client
from typing import Any, List, Mapping, Optional, Sequence

from cnr_harness.process import Proc, free_port, wait_until


def master_proxy(uri: str, timeout: float, compressed: bool = True) -> xmlrpc.client.ServerProxy:
    """An XML-RPC proxy of the master (or any node) at ``uri`` whose calls give up after ``timeout`` seconds. Its
    calls share one kept-alive connection (HTTP/1.1). ``compressed=False``: answers are not asked gzipped (xmlrpc
    compresses those above 1400 B when the client accepts it: CPU for the master, for nothing on one host or a
    LAN; getSystemState's answer is tens of KB)."""
    return xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout, compressed))


def master_answers(uri: str, caller: str = '/cnr_harness', timeout: float = 1.0) -> bool:
    """Whether a ROS master answers ``getPid`` at ``uri`` within ``timeout`` seconds."""
    proxy = master_proxy(uri, timeout)
    try:
        return proxy.getPid(caller)[0] == 1
    except (OSError, xmlrpc.client.Error):
        return False


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout: float, compressed: bool = True) -> None:
        super().__init__()
        self._timeout = timeout
        self.accept_gzip_encoding = compressed

    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = self._timeout
        return conn


class RosMaster:
    """A ROS master on a free port (never 11311) plus the processes started against it.

    Args:
        log_dir: where the output of the master and of :meth:`run` processes goes (default: a new temp dir).
        host: the address the master is reached at and ``ROS_IP`` of the processes.
        port: the port (default: a free one).
        env: base environment of the processes (default: this process's); ``ROS_MASTER_URI`` and ``ROS_IP``
            are set, ``ROS_HOSTNAME`` removed.
        roscore: start ``roscore`` (master and rosout) instead of ``rosmaster --core``.
        multi_master: start the master of one host of several, :mod:`cnr_harness.rosmaster` (as the testbed's
            hosts and ``ros_master.sh --multi-master`` do), instead of ``rosmaster --core``.
        use_sim_time: if not ``None``, ``/use_sim_time`` is set to it once the master answers.
        timeout: seconds to wait for the master to answer.
        caller: the caller id of the harness's own master calls.
    """

    def __init__(self, log_dir: Optional[str] = None, host: str = '127.0.0.1', port: int = 0,
                 env: Optional[Mapping[str, str]] = None, roscore: bool = False,
                 use_sim_time: Optional[bool] = None, timeout: float = 20.0, caller: str = '/cnr_harness',
                 multi_master: bool = False) -> None:
        self.log_dir = log_dir or tempfile.mkdtemp(prefix='cnr-harness-')
        self.port = port or free_port(host)
        self.uri = f'http://{host}:{self.port}/'
        self.caller = caller
        self.env = dict(os.environ if env is None else env, ROS_MASTER_URI=self.uri, ROS_IP=host)
        self.env.pop('ROS_HOSTNAME', None)
        self.children: List[Proc] = []
        argv = ['roscore', '-p', str(self.port)] if roscore else \
            [sys.executable, '-m', 'cnr_harness.rosmaster', '--core', '-p', str(self.port)] if multi_master else \
            ['rosmaster', '--core', '-p', str(self.port)]
        self.proc = Proc(argv, self.log_path('roscore' if roscore else 'rosmaster'), self.env)
        try:
            wait_until(self.answers, timeout, f'the rosmaster on port {self.port}', self.proc)
            if use_sim_time is not None:
                self.call('setParam', '/use_sim_time', use_sim_time)
        except BaseException:
            self.proc.stop()
            raise

    def log_path(self, name: str) -> str:
        """A new log file name in :attr:`log_dir` for a process called ``name``."""
        return os.path.join(self.log_dir, f'{name}-{os.getpid()}-{time.monotonic_ns()}.log')

    def answers(self) -> bool:
        return master_answers(self.uri, self.caller)

    def call(self, method: str, *args: Any) -> Any:
        """One Master API call; returns its value, raises RuntimeError on a failure code."""
        code, msg, value = getattr(xmlrpc.client.ServerProxy(self.uri), method)(self.caller, *args)
        if code != 1:
            raise RuntimeError(f'{method}{args}: {msg}')
        return value

    def node_names(self) -> List[str]:
        names = set()
        for group in self.call('getSystemState'):
            for _, nodes in group:
                names.update(nodes)
        return sorted(names)

    def run(self, argv: Sequence[str], log_name: str = 'proc', env: Optional[Mapping[str, str]] = None) -> Proc:
        """Start ``argv`` against this master (own process group, output in :attr:`log_dir`); stopped by :meth:`stop`."""
        proc = Proc(argv, self.log_path(log_name), dict(self.env, **(env or {})))
        self.children.append(proc)
        return proc

    def roslaunch(self, package: str, launch_file: str, *args: str) -> Proc:
        return self.run(['roslaunch', package, launch_file, *args], log_name=launch_file)

    def stop_child(self, proc: Proc, timeout: float = 10.0) -> Optional[int]:
        code = proc.stop(timeout)
        if proc in self.children:
            self.children.remove(proc)
        return code

    def stop(self) -> None:
        """Stop the processes started by :meth:`run`, newest first, then the master."""
        for proc in reversed(self.children):
            proc.stop()
        self.children.clear()
        self.proc.stop()

    def __enter__(self) -> 'RosMaster':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
