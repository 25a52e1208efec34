"""CPU priority of the control plane (ROS-free).

On the robot the modules, the master and the bridge share one small computer that is often saturated (the
testbed's CPU cap is throttled in most periods during a mission). Work that keeps the system together queues
behind bulk work (costmaps, point clouds) there: a hand-over or a lease renewal stretches the downtime and can
make a lease lapse, and the bridge's re-registration of a peer after an outage (one batch of master calls) leaves
the graph incomplete for longer. The control plane therefore runs at a nice value of its own:
migration_manager's manager and the threads of a managed instance that carry the protocol (its renewal loop, its
lease and control callbacks) at ``control_nice`` (config/migration.yaml), the multimaster bridge at its ``nice``
(config/bridge.yaml). Linux nice values are per thread and a new thread inherits its creator's, so a module's
own work keeps its priority.

A promoted instance's own threads carry the hand-over's critical path too (its state restored, its action
server started, its first control cycle, its publishers' writer threads), so :meth:`Elevator.boost` gives every
thread of the process the same value for a while after a promotion (``promotion_boost``); then each gets its
own back.

A negative value needs CAP_SYS_NICE (root); without it the threads keep their priority and :class:`Elevator`
reports that once.
"""
from __future__ import annotations

import os
import threading
import time
from typing import Callable, Dict, Optional, Set


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
        self.boosted: Dict[int, int] = {}        # thread -> its nice before the boost in progress
        self.boost_until = 0.0                   # monotonic end of the boost in progress
        self.seen: Set[int] = set()              # the threads that existed when it began

    def this_thread(self) -> None:
        """Elevate the calling thread (cheap after the first call from a thread)."""
        self._elevate(threading.get_native_id())

    def whole_process(self) -> None:
        """Elevate every thread of this process (threads it creates later inherit the value)."""
        for tid in _threads():
            self._elevate(tid)

    def boost(self, seconds: float) -> None:
        """Every thread of this process at the control plane's value for ``seconds`` (a later boost extends it);
        then each boosted thread gets back the value it had, and a thread created meanwhile (it inherited the
        boost) the process's main thread's. Threads elevated for good (:meth:`this_thread`) stay."""
        if self.nice == 0 or seconds <= 0:
            return
        with self.lock:
            first = not self.boosted
            self.boost_until = max(self.boost_until, time.monotonic() + seconds)
            threads = _threads()
            if first:
                self.seen = set(threads)
            for tid in threads:
                if tid in self.done or tid in self.boosted:
                    continue
                try:
                    before = thread_nice(tid)
                except ProcessLookupError:
                    continue
                if before <= self.nice:
                    continue
                self.boosted[tid] = before
                self._set(tid, self.nice)
        if first:
            timer = threading.Timer(seconds, self._end_boost)
            timer.daemon = True
            timer.start()

    def _end_boost(self) -> None:
        with self.lock:
            left = self.boost_until - time.monotonic()
            if left > 0.001:                     # extended: look again then
                timer = threading.Timer(left, self._end_boost)
                timer.daemon = True
                timer.start()
                return
            base = self.boosted.get(os.getpid(), thread_nice(os.getpid()))
            for tid in _threads():
                if tid in self.boosted:
                    set_thread_nice(tid, self.boosted[tid])
                elif tid not in self.done and tid not in self.seen:      # created meanwhile: inherited it
                    set_thread_nice(tid, base)
            self.boosted, self.seen = {}, set()

    def _set(self, tid: int, nice: int) -> None:
        problem = set_thread_nice(tid, nice)
        if problem and not self.failed:
            self.failed = True
            self.warn(f'control plane priority: {problem}; those threads keep their priority')

    def _elevate(self, tid: int) -> None:
        if self.nice == 0 or tid in self.done:
            return
        with self.lock:
            if tid in self.done:
                return
            self.done.add(tid)
            self._set(tid, self.nice)


def _threads() -> list:
    """This process's threads (native ids)."""
    return [int(name) for name in os.listdir('/proc/self/task')]
