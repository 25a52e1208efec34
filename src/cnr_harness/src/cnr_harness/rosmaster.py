"""rosmaster with a notification dispatcher that never lets one node hold up another's (``python3 -m
cnr_harness.rosmaster [rosmaster's arguments]``, e.g. ``--core -p 11311``).

A master tells each subscriber of a topic about a new publisher (``publisherUpdate``, an XML-RPC call to the
subscriber's node) from a pool of threads, rosmaster's ``MarkedThreadPool``: 3 threads by default, the calls to one
node one at a time. In a multi-master set-up the other host's subscribers are registered here by the bridge with
their own addresses, so some of these calls cross the link; with the link down each hangs until TCP gives up (7 s
for a connection with the retransmission timeout capped at 1 s, 127 s without). With 3 threads a few such calls
stall every notification behind them, this host's own nodes' too: a robot node does not hear of a new local
publisher, and a restarted module instance is not heard by the migration manager, until the link has been back for
a while. More threads do not help at a price worth paying: an idle pool thread polls for work 10 times a second
(``rosmaster -w 64`` idles at 0.11 CPU, 0.002 with 3 threads; on the robot's CPU cap a third of its budget).

:class:`NodeDispatcher` keeps the pool's semantics per node and nothing else: the tasks of one marker (a node's
XML-RPC URI) run in order, in a thread that exists while that node has work; another node's tasks never wait behind
them; no thread polls.
"""
from __future__ import annotations

import logging
import sys
import threading
import traceback
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Tuple

Task = Tuple[Callable[..., Any], tuple, Optional[Callable[[Any], None]]]


class NodeDispatcher:
    """A drop-in for ``rosmaster.threadpool.MarkedThreadPool`` (``queue_task``, ``join_all``, the thread count):
    per marker, tasks run in order in a thread of their own while there are any (module docstring). ``threads`` is
    rosmaster's worker count (``-w``), not used: a node's calls never wait for another node's."""

    def __init__(self, threads: int = 0) -> None:
        self._lock = threading.Lock()
        self._queues: Dict[Any, Deque[Task]] = {}
        self._joining = False

    def queue_task(self, marker: Any, task: Callable[..., Any], args: Optional[tuple] = None,
                   taskCallback: Optional[Callable[[Any], None]] = None) -> bool:
        if self._joining or not callable(task):
            return False
        key = marker if marker is not None else object()       # no marker: no order to keep
        with self._lock:
            queue = self._queues.get(key)
            if queue is not None:                               # its thread is draining it
                queue.append((task, tuple(args or ()), taskCallback))
                return True
            self._queues[key] = deque([(task, tuple(args or ()), taskCallback)])
        threading.Thread(target=self._drain, args=(key,), name='master-notify', daemon=True).start()
        return True

    def _drain(self, key: Any) -> None:
        while True:
            with self._lock:
                queue = self._queues[key]
                if not queue or self._joining:
                    del self._queues[key]
                    return
                task, args, callback = queue.popleft()
            try:
                result = task(*args)
                if callback is not None:
                    callback(result)
            except Exception:                                   # as rosmaster's pool: logged, the next task runs
                logging.getLogger('rosmaster.threadpool').error(traceback.format_exc())

    def pending(self) -> int:
        """Tasks queued or running (for tests)."""
        with self._lock:
            return sum(len(q) for q in self._queues.values()) + len(self._queues)

    def join_all(self, wait_for_tasks: bool = True, wait_for_threads: bool = True) -> None:
        """At shutdown: no new tasks; queued ones are dropped (the master is going away)."""
        self._joining = True

    def set_thread_count(self, threads: int) -> bool:
        return not self._joining

    def get_thread_count(self) -> int:
        with self._lock:
            return len(self._queues)


def main(argv: Optional[List[str]] = None) -> None:
    import rosmaster.main
    import rosmaster.threadpool
    rosmaster.threadpool.MarkedThreadPool = NodeDispatcher     # master_api looks it up when the master starts
    rosmaster.main.rosmaster_main(['rosmaster', *(sys.argv[1:] if argv is None else argv)])


if __name__ == '__main__':
    main()
