"""rosmaster with a notification dispatcher that never lets one node hold up another's (``python3 -m
cnr_harness.rosmaster [rosmaster's arguments]``, e.g. ``--core -p 11311``).

A master tells each subscriber of a topic about a new publisher (``publisherUpdate``, an XML-RPC call to the
subscriber's node) from a pool of threads, rosmaster's ``MarkedThreadPool``: 3 threads by default, the calls to one
node one at a time. In a multi-master set-up the other host's subscribers are registered here by the bridge with
their own addresses, so some of these calls cross the link; with the link down each hangs until TCP gives up (127
s for a connection, minutes for a request already sent). With 3 threads a few such calls
stall every notification behind them, this host's own nodes' too: a robot node does not hear of a new local
publisher, and a restarted module instance is not heard by the migration manager, until the link has been back for
a while. More threads do not help at a price worth paying: an idle pool thread polls for work 10 times a second
(``rosmaster -w 64`` idles at 0.11 CPU, 0.002 with 3 threads; on the robot's CPU cap a third of its budget), and
after an outage, when the bridge registers the other host's hundred-odd registrations again at once, every
notification running at the same time slowed the master's answers to the bridge itself (bench_flap.sh, the same
1.8 s cut of the same schedule: re-registered in 2.7 s with them all at once, 0.33 s with rosmaster's pool).

:class:`NodeDispatcher` keeps the pool's semantics and bounds what hangs: the tasks of one marker (a node's XML-RPC
URI) run in order, in a thread that exists while that node has work; at most ``threads`` calls run at once, as in
rosmaster's pool, but a call that has not returned within ``hang_after`` seconds stops counting (it waits on a dead
link or a hung node), so it never holds up another node's; no thread polls.

Two more, for a burst of registrations such as a peer's after an outage (the bridge sends them in one
``system.multicall``): the notifications the calls of a multicall set off are held until the multicall has been
answered (the answer no longer competes with them for the interpreter and a capped CPU), and a queued
``publisherUpdate`` that a newer one for the same node and topic supersedes is dropped (each carries the topic's
whole list of publishers, so only the newest counts): a peer's 30 publishers on 20 topics notify each subscriber once
per topic, not once per publisher.

And the graph's answers are kept: ``getSystemState`` and ``getTopicTypes`` depend on the registrations only (not on
the caller), yet every poll had the master build and marshal them anew — 0.65 ms of its CPU for 40 nodes of 9
registrations each (0.15 ms kept), and the bridge polls at 10 Hz on a CPU-capped robot. :class:`GraphAnswers` keeps each one's
marshalled answer until a registration call (``register*``/``unregister*``) has returned since it was made.
"""
from __future__ import annotations

import functools
import logging
import sys
import threading
import time
import traceback
import xmlrpc.client
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Optional, Set

Task = List[Any]         # [function, args, callback]: args replaced in place when a newer notification supersedes it
HANG_AFTER = 0.25       # s a notification call may take before it stops counting against the pool's size (one
                        # across a dead link never returns; a slow local one only lets one more call run)


_batch = threading.local()      # .held: (dispatcher, marker) whose drain waits for the current multicall's answer


def publisher_update_task() -> Optional[Callable[..., Any]]:
    """rosmaster's ``publisherUpdate`` task (args: node API, topic, the topic's publishers), None without rosmaster."""
    try:
        from rosmaster.master_api import publisher_update_task as task
    except ImportError:
        return None
    return task


class NodeDispatcher:
    """A drop-in for ``rosmaster.threadpool.MarkedThreadPool`` (``queue_task``, ``join_all``, the thread count):
    per marker, tasks run in order in a thread of their own while there are any; at most ``threads`` (rosmaster's
    ``-w``) at once, a call counting for ``hang_after`` seconds at most (module docstring)."""

    def __init__(self, threads: int, hang_after: float = HANG_AFTER) -> None:
        self._lock = threading.Lock()
        self._queues: Dict[Any, Deque[Task]] = {}
        self._draining: Set[Any] = set()            # markers whose thread is running
        self._superseded = publisher_update_task()
        self._joining = False
        self.hang_after = hang_after
        self._slots = threading.Condition()         # guards the two below
        self._free = max(1, threads)
        self._counting: Dict[int, float] = {}      # running call -> monotonic time it stops counting
        self._calls = 0

    def queue_task(self, marker: Any, task: Callable[..., Any], args: Optional[tuple] = None,
                   taskCallback: Optional[Callable[[Any], None]] = None) -> bool:
        if self._joining or not callable(task):
            return False
        key = marker if marker is not None else object()       # no marker: no order to keep
        args = tuple(args or ())
        held = getattr(_batch, 'held', None)
        with self._lock:
            queue = self._queues.setdefault(key, deque())
            if not self._supersede(queue, task, args, taskCallback):
                queue.append([task, args, taskCallback])
            if key in self._draining:                           # its thread takes it
                return True
            if held is not None:                                # started once the multicall is answered
                held.append((self, key))
                return True
            self._draining.add(key)
        self._start(key)
        return True

    def _supersede(self, queue: Deque[Task], task: Callable[..., Any], args: tuple,
                   callback: Optional[Callable[[Any], None]]) -> bool:
        """A queued publisherUpdate of the same node and topic takes the newer list instead (module docstring)."""
        if task is not self._superseded or callback is not None or len(args) != 3:
            return False
        for queued in queue:
            if queued[0] is task and queued[2] is None and queued[1][:2] == args[:2]:
                queued[1] = args
                return True
        return False

    def _start(self, key: Any) -> None:
        threading.Thread(target=self._drain, args=(key,), name='master-notify', daemon=True).start()

    def release(self, keys: List[Any]) -> None:
        """Start draining the queues held during a multicall."""
        start = []
        with self._lock:
            for key in dict.fromkeys(keys):
                if key not in self._draining and self._queues.get(key):
                    self._draining.add(key)
                    start.append(key)
        for key in start:
            self._start(key)

    def _drain(self, key: Any) -> None:
        while True:
            with self._lock:
                queue = self._queues[key]
                if not queue or self._joining:
                    del self._queues[key]
                    self._draining.discard(key)
                    return
                task, args, callback = queue.popleft()
            call = self._start_call()
            try:
                result = task(*args)
                if callback is not None:
                    callback(result)
            except Exception:                                   # as rosmaster's pool: logged, the next task runs
                logging.getLogger('rosmaster.threadpool').error(traceback.format_exc())
            finally:
                self._end_call(call)

    def _start_call(self) -> int:
        """Wait for a free place (a call that returned, or one that stopped counting: no timer thread, a waiter
        frees those itself) and take it."""
        with self._slots:
            while self._free == 0:
                now = time.monotonic()
                for call in [c for c, until in self._counting.items() if until <= now]:
                    del self._counting[call]
                    self._free += 1
                if self._free == 0:
                    self._slots.wait(min(self._counting.values()) - now)
            self._free -= 1
            self._calls += 1
            self._counting[self._calls] = time.monotonic() + self.hang_after
            return self._calls

    def _end_call(self, call: int) -> None:
        with self._slots:
            if self._counting.pop(call, None) is not None:      # not already given up as hung
                self._free += 1
                self._slots.notify()

    def pending(self) -> int:
        """Tasks queued, and queues being drained (for tests)."""
        with self._lock:
            return sum(len(q) for q in self._queues.values()) + len(self._draining)

    def join_all(self, wait_for_tasks: bool = True, wait_for_threads: bool = True) -> None:
        """At shutdown: no new tasks; queued ones are dropped (the master is going away)."""
        self._joining = True

    def set_thread_count(self, threads: int) -> bool:
        return not self._joining

    def get_thread_count(self) -> int:
        with self._lock:
            return len(self._draining)


def hold_during_multicall(multicall: Callable[[Any, list], list]) -> Callable[[Any, list], list]:
    """``SimpleXMLRPCDispatcher.system_multicall`` that holds the notifications its calls set off until it returns
    (module docstring)."""
    def system_multicall(server: Any, call_list: list) -> list:
        outer = getattr(_batch, 'held', None)
        _batch.held = held = [] if outer is None else outer
        try:
            return multicall(server, call_list)
        finally:
            if outer is None:
                _batch.held = None
                by_dispatcher: Dict[NodeDispatcher, List[Any]] = {}
                for dispatcher, key in held:
                    by_dispatcher.setdefault(dispatcher, []).append(key)
                for dispatcher, keys in by_dispatcher.items():
                    dispatcher.release(keys)
    system_multicall.__doc__ = multicall.__doc__
    return system_multicall


GRAPH_QUERIES = (b'getSystemState', b'getTopicTypes')    # answers that depend on the registrations only
GRAPH_CHANGES = ('registerPublisher', 'unregisterPublisher', 'registerSubscriber', 'unregisterSubscriber',
                 'registerService', 'unregisterService')   # rosmaster's only calls that change them (a node at a
                                                           # new URI loses its old registrations inside one)


class GraphAnswers:
    """The marshalled answers to :data:`GRAPH_QUERIES`, each kept with the graph's version it was computed at.

    The version goes up when a call of :data:`GRAPH_CHANGES` returns (its change is in place by then); a query
    reads the version *before* it computes its answer, so an answer that a change overtook is kept under the
    older version and never served again. A call with anything but one string argument (the caller id) goes to
    rosmaster as it is."""

    def __init__(self) -> None:
        self.version = 0
        self._lock = threading.Lock()
        self._answers: Dict[bytes, Any] = {}        # method -> (version, marshalled answer)

    def changed(self) -> None:
        with self._lock:
            self.version += 1

    def changing(self, call: Callable[..., Any]) -> Callable[..., Any]:
        """A registration call of rosmaster's handler that bumps the version once it has returned."""
        @functools.wraps(call)
        def bump(*args: Any, **kwargs: Any) -> Any:
            try:
                return call(*args, **kwargs)
            finally:
                self.changed()
        return bump

    @staticmethod
    def query(data: bytes) -> Optional[bytes]:
        """The graph query ``data`` (an XML-RPC request) asks, if it is one, else None."""
        for method in GRAPH_QUERIES:
            if b'<methodName>' + method + b'</methodName>' in data:
                params, name = xmlrpc.client.loads(data)
                if name == method.decode() and len(params) == 1 and isinstance(params[0], str):
                    return method
        return None

    def dispatching(self, dispatch: Callable[..., bytes]) -> Callable[..., bytes]:
        """``SimpleXMLRPCDispatcher._marshaled_dispatch`` that answers a graph query from what it keeps."""
        def _marshaled_dispatch(server: Any, data: bytes, dispatch_method: Any = None, path: Any = None) -> bytes:
            try:
                method = self.query(data)
            except Exception:                   # noqa: BLE001 - not a request it can read: rosmaster's error
                method = None
            if method is None:
                return dispatch(server, data, dispatch_method, path)
            with self._lock:
                version = self.version
                kept = self._answers.get(method)
            if kept is not None and kept[0] == version:
                return kept[1]
            answer = dispatch(server, data, dispatch_method, path)
            if b'<fault>' not in answer:
                with self._lock:
                    self._answers[method] = (version, answer)
            return answer
        _marshaled_dispatch.__doc__ = dispatch.__doc__
        return _marshaled_dispatch


def main(argv: Optional[List[str]] = None) -> None:
    import rosmaster.main
    import rosmaster.master_api
    import rosmaster.threadpool
    args = sys.argv[1:] if argv is None else argv
    rosmaster.threadpool.MarkedThreadPool = NodeDispatcher     # master_api looks it up when the master starts
    from xmlrpc.server import SimpleXMLRPCDispatcher            # bound by register_multicall_functions at start
    SimpleXMLRPCDispatcher.system_multicall = hold_during_multicall(SimpleXMLRPCDispatcher.system_multicall)
    answers = GraphAnswers()
    handler = rosmaster.master_api.ROSMasterHandler
    for name in GRAPH_CHANGES:                                  # looked up per call by the server's _dispatch
        setattr(handler, name, answers.changing(getattr(handler, name)))
    SimpleXMLRPCDispatcher._marshaled_dispatch = answers.dispatching(SimpleXMLRPCDispatcher._marshaled_dispatch)
    rosmaster.main.rosmaster_main(['rosmaster', *args])


if __name__ == '__main__':
    main()
