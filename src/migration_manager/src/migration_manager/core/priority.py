"""CPU priority of the migration's control plane (ROS-free).

On the robot the modules, the master and the bridge share one small computer that is often saturated (the
testbed's CPU cap is throttled in most periods during a mission). A hand-over or a lease renewal that queues
behind bulk work (costmaps, the bridge's polling) stretches the downtime and can make a lease lapse. The
manager and the threads of a managed instance that carry the protocol (its renewal loop, its lease and control
callbacks) therefore run at ``control_nice`` (config/migration.yaml): Linux nice values are per thread and a
new thread inherits its creator's, so the module's own work keeps its priority.

A negative value needs CAP_SYS_NICE (root); without it the threads keep their priority and :class:`Elevator`
reports that once.
"""
from __future__ import annotations

import os
import threading
from typing import Callable, Optional, Set


def set_thread_nice(tid: int, nice: int) -> Optional[str]:
    """Give the thread ``tid`` (a native thread id) the nice value; None when done, else why not."""
    try:
        os.setpriority(os.PRIO_PROCESS, tid, nice)
        return None
    except PermissionError:
        return f'cannot set nice {nice} (negative values need CAP_SYS_NICE or root)'
    except ProcessLookupError:
        return None                              # the thread has ended meanwhile


def thread_nice(tid: int) -> int:
    return os.getpriority(os.PRIO_PROCESS, tid)


class Elevator:
    """Gives threads the control plane's nice value, each once; ``warn`` is called once if it cannot."""

    def __init__(self, nice: int, warn: Callable[[str], None]) -> None:
        self.nice = nice
        self.warn = warn
        self.done: Set[int] = set()
        self.lock = threading.Lock()
        self.failed = False

    def this_thread(self) -> None:
        """Elevate the calling thread (cheap after the first call from a thread)."""
        self._elevate(threading.get_native_id())

    def whole_process(self) -> None:
        """Elevate every thread of this process (threads it creates later inherit the value)."""
        for name in os.listdir('/proc/self/task'):
            self._elevate(int(name))

    def _elevate(self, tid: int) -> None:
        if self.nice == 0 or tid in self.done:
            return
        with self.lock:
            if tid in self.done:
                return
            self.done.add(tid)
            problem = set_thread_nice(tid, self.nice)
            if problem and not self.failed:
                self.failed = True
                self.warn(f'control plane priority: {problem}; those threads keep their priority')
