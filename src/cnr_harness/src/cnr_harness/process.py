"""Processes in their own process group, stopped like roslaunch stops nodes, and polling waits.

No ROS imports: usable from tests, benchmarks and tools alike.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from typing import Callable, Mapping, Optional, Sequence, TypeVar

T = TypeVar('T')
ROS_DEFAULT_PORT = 11311


class WaitTimeout(RuntimeError):
    """A :func:`wait_until` that ran out of time, or whose watched process exited first."""


def free_port(host: str = '127.0.0.1') -> int:
    """A TCP port the OS reports free on ``host`` (never ROS's default 11311)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind((host, 0))
            port = s.getsockname()[1]
        if port != ROS_DEFAULT_PORT:
            return port


def wait_until(condition: Callable[[], T], timeout: float, what: str, proc: Optional['Proc'] = None,
               interval: float = 0.05) -> T:
    """Poll ``condition`` until it returns a truthy value and return that value.

    Args:
        condition: called every ``interval`` seconds.
        timeout: wall seconds before giving up.
        what: what is waited for, for the error message.
        proc: if given, fail at once when this process exits (the message names its log file).
        interval: seconds between polls.

    Raises:
        WaitTimeout: after ``timeout`` s, or when ``proc`` exits first.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            raise WaitTimeout(f'{what}: process exited with {proc.returncode} (see {proc.log_path})')
        if time.monotonic() > deadline:
            raise WaitTimeout(f'timed out after {timeout:.1f} s waiting for {what}')
        time.sleep(interval)


def stop_process(popen: subprocess.Popen, timeout: float = 10.0, term_timeout: float = 3.0,
                 kill_timeout: float = 3.0) -> Optional[int]:
    """Stop ``popen``'s process group: SIGINT (as roslaunch does), then SIGTERM, then SIGKILL.

    Each signal gets its own timeout in seconds; an already exited leader still has its group killed
    (children it left behind). Returns the exit status (``None`` if even SIGKILL did not end it).
    """
    if popen.poll() is None:
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, term_timeout), (signal.SIGKILL, kill_timeout)):
            try:
                os.killpg(popen.pid, sig)
            except ProcessLookupError:
                break
            try:
                popen.wait(wait)
                break
            except subprocess.TimeoutExpired:
                continue
    else:
        try:
            os.killpg(popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    return popen.returncode


class Proc:
    """A child process in its own process group (session), its output (stdout and stderr) in ``log_path``.

    The child runs with ``PYTHONUNBUFFERED=1`` so that Python output reaches the file as it is written,
    whatever the caller's environment. stdin is ``/dev/null``.

    Args:
        argv: the command.
        log_path: file for the output (created, directories too).
        env: the child's environment (default: this process's); ``PYTHONUNBUFFERED=1`` is added.
    """

    def __init__(self, argv: Sequence[str], log_path: str, env: Optional[Mapping[str, str]] = None) -> None:
        self.argv = list(argv)
        self.log_path = log_path
        os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
        child_env = dict(os.environ if env is None else env, PYTHONUNBUFFERED='1')
        with open(log_path, 'wb') as log:
            self.popen = subprocess.Popen(self.argv, env=child_env, stdout=log, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, start_new_session=True)

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def returncode(self) -> Optional[int]:
        return self.popen.returncode

    def poll(self) -> Optional[int]:
        return self.popen.poll()

    def alive(self) -> bool:
        return self.popen.poll() is None

    def wait(self, timeout: Optional[float] = None) -> int:
        return self.popen.wait(timeout)

    def output(self) -> str:
        """Everything the process has written so far."""
        with open(self.log_path, 'r', errors='replace') as f:
            return f.read()

    def stop(self, timeout: float = 10.0) -> Optional[int]:
        """Stop the process group (see :func:`stop_process`); returns the exit status."""
        return stop_process(self.popen, timeout)

    def __repr__(self) -> str:
        return f'Proc({self.argv!r}, pid={self.pid}, log={self.log_path})'
