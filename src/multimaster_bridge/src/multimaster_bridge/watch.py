"""Watch two bridged masters and time how long the registrations across take to come back after each outage.

:class:`RestoreWatch` polls both masters' ``getSystemState`` (and ``lookupNode`` for the proxies and the nodes they
stand for) in a thread and checks the invariant of :mod:`multimaster_bridge.core.invariant` at every poll; the caller
says when each outage began and ended, and :meth:`RestoreWatch.results` gives, per outage, the time from the link's
return to the moment from which the invariant held until the next outage::

    watch = RestoreWatch(robot_uri, cloud_uri, ['config/bridge.yaml', 'config/bridge_robot.yaml'],
                         ['config/bridge.yaml', 'config/bridge_cloud.yaml'],
                         robot_netns='robot', cloud_netns='cloud', enter=cnr_testbed.netns.inside).start()
    watch.outage_began(); ...; watch.outage_ended()      # times: time.monotonic() unless given
    ...
    summary = watch.stop().results()                     # RestoreResults: .restores, .median, .max, .unrestored

A master inside a network namespace (the testbed's) is reached from inside it: ``*_netns`` names the namespace and
``enter`` is the context manager that runs the calling thread inside one (``cnr_testbed.netns.inside``; root).
Times are ``time.monotonic()``.
"""
from __future__ import annotations

import contextlib
import http.client
import math
import statistics
import threading
import time
import xmlrpc.client
from dataclasses import dataclass, field
from typing import Any, Callable, ContextManager, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

import yaml

from cnr_harness.master import master_proxy
from multimaster_bridge.core import restore
from multimaster_bridge.core.invariant import Filters, MasterView, Side, discrepancies, proxy_nodes
from multimaster_bridge.core.sync import Filter

BridgeCfg = Union[str, Mapping[str, Any], Sequence[Union[str, Mapping[str, Any]]]]
Enter = Callable[[str], ContextManager[None]]     # namespace name -> runs the calling thread inside it


def bridge_filters(cfg: BridgeCfg) -> Tuple[str, Filters]:
    """(name, filters) of a bridge's configuration: a mapping of its parameters, a YAML file, or a list of either
    overlaid in order (as bridge.launch loads config/bridge.yaml, then the host's file)."""
    layers = [cfg] if isinstance(cfg, (str, Mapping)) else list(cfg)
    merged: Dict[str, Any] = {}
    for layer in layers:
        if isinstance(layer, str):
            with open(layer) as f:
                layer = yaml.safe_load(f) or {}
        merged.update(layer)
    if not merged.get('name'):
        raise ValueError(f'bridge configuration {cfg!r}: name: missing')

    def globs(key: str) -> List[str]:
        value = merged.get(key) or []
        return [value] if isinstance(value, str) else list(value)
    return (str(merged['name']).strip('/'),
            Filters(Filter(globs('allow_topics'), globs('deny_topics')),
                    Filter(globs('allow_services'), globs('deny_services'))))


class MasterReader:
    """Master API calls to one master, from inside network namespace ``netns`` (entered by ``enter``) if given,
    over one kept-alive connection (opened inside the namespace) and with uncompressed answers: a new
    connection and a gzipped getSystemState at each poll cost the master 1.25 ms of CPU, 0.15 ms so (the
    watch's own load on a CPU-capped master is load on what it measures). A call gives up after ``timeout``
    seconds."""

    def __init__(self, uri: str, netns: Optional[str] = None, enter: Optional[Enter] = None,
                 caller_id: str = '/restore_watch', timeout: float = 10.0) -> None:
        if netns is not None and enter is None:
            raise ValueError(f'enter: needed to reach the master {uri} inside the namespace {netns!r} '
                             f'(e.g. cnr_testbed.netns.inside)')
        self.uri = uri
        self.netns = netns
        self.enter = enter
        self.caller_id = caller_id
        self.timeout = timeout
        self._proxy: Optional[xmlrpc.client.ServerProxy] = None
        self._lock = threading.Lock()               # one call at a time on the connection

    def _call(self, call: Callable[[xmlrpc.client.ServerProxy], Any]) -> Any:
        """``call(proxy)`` inside the namespace; after a failure the next call connects anew."""
        with self._lock, self._place():
            if self._proxy is None:
                self._proxy = master_proxy(self.uri, self.timeout, compressed=False)
            try:
                return call(self._proxy)
            except (OSError, xmlrpc.client.Error, http.client.HTTPException):
                self._proxy = None
                raise

    @contextlib.contextmanager
    def _place(self) -> Iterator[None]:
        if self.netns is None or self.enter is None:
            yield
            return
        with self.enter(self.netns):
            yield

    def system_state(self) -> Tuple[list, list, list]:
        code, msg, state = self._call(lambda m: m.getSystemState(self.caller_id))
        if code != 1:
            raise RuntimeError(f'getSystemState at {self.uri}: {msg}')
        return state

    def node_uris(self, nodes: Sequence[str]) -> Dict[str, str]:
        if not nodes:
            return {}
        def lookup(master: xmlrpc.client.ServerProxy) -> list:
            multi = xmlrpc.client.MultiCall(master)
            for n in nodes:
                multi.lookupNode(self.caller_id, n)
            return list(multi())
        answers = self._call(lookup)
        return {n: uri for n, (code, _, uri) in zip(nodes, answers) if code == 1}


def check_at(a: Tuple[str, MasterReader, Filters], b: Tuple[str, MasterReader, Filters],
             known: Optional[Dict[str, Dict[str, str]]] = None) -> Tuple[float, List[str]]:
    """The invariant's discrepancies between two live masters (``(bridge name, reader, filters)`` each), one per
    registration (:func:`multimaster_bridge.core.invariant.discrepancies`), and the time (``time.monotonic()``) by
    which both masters had answered with their registrations: what they showed held by then. The URIs are looked up
    only once the registrations match, and only those not in ``known`` (bridge name -> node -> URI, filled here: a
    caller that keeps it between checks clears it now and then); those lookups take more round trips to a master (a
    CPU-capped one answers slowly), and the time is not theirs."""
    sides = [Side(name, MasterView.from_system_state(reader.system_state()), filters)
             for name, reader, filters in (a, b)]
    read_at = time.monotonic()
    wrong = discrepancies(*sides)
    if wrong:
        return read_at, wrong
    known = {} if known is None else known
    readers = {a[0]: a[1], b[0]: b[1]}
    for here, there in ((sides[0], sides[1]), (sides[1], sides[0])):
        mine = proxy_nodes(here, there.name)
        theirs = {'/' + n[len(there.name) + 2:] for n in mine}
        for side, names in ((here, mine), (there, theirs)):
            cache = known.setdefault(side.name, {})
            cache.update(readers[side.name].node_uris(sorted(n for n in names if n not in cache)))
            side.view.uris.update({n: cache[n] for n in names if n in cache})
    return read_at, discrepancies(*sides)


@dataclass
class RestoreResults:
    """Per outage, two measures of the registrations' return (None: not restored before the next outage began or
    the watch ended):

    - ``restores``: seconds from the link's return until the invariant held for good (unbroken until the next
      outage);
    - ``lags``: the longest any one discrepancy lasted, counted from the link's return, or from when it arose if
      that was later (the peer registered something after the return, e.g. a module's new instance): how long the
      bridge took to bring each registration across, whatever else changed meanwhile.
    """
    restores: List[Optional[float]] = field(default_factory=list)
    last_problems: List[List[str]] = field(default_factory=list)   # per outage: what was wrong last (if anything)
    lags: List[Optional[float]] = field(default_factory=list)

    @property
    def restored(self) -> List[float]:
        return [r for r in self.restores if r is not None]

    @property
    def unrestored(self) -> int:
        return sum(r is None for r in self.restores)

    @property
    def median(self) -> Optional[float]:
        return statistics.median(self.restored) if self.restored else None

    @property
    def max(self) -> Optional[float]:
        return max(self.restored) if self.restored else None


class RestoreWatch:
    """Polls two bridged masters every ``interval`` s in a thread and times each restore of the invariant.

    Args:
        robot_master_uri, cloud_master_uri: the masters' URIs.
        robot_bridge_cfg, cloud_bridge_cfg: each bridge's configuration (see :func:`bridge_filters`).
        robot_netns, cloud_netns: network namespaces to reach the masters from (the testbed's), or None.
        enter: runs the calling thread inside a named namespace (``cnr_testbed.netns.inside``); needed with a
            namespace.
        interval: seconds between polls (the resolution of the restore times). Each poll is one getSystemState per
            master (and lookupNode for nodes new to the watch, and for all of them once a second).
    """

    def __init__(self, robot_master_uri: str, cloud_master_uri: str, robot_bridge_cfg: BridgeCfg,
                 cloud_bridge_cfg: BridgeCfg, robot_netns: Optional[str] = None, cloud_netns: Optional[str] = None,
                 enter: Optional[Enter] = None, interval: float = 0.05) -> None:
        robot_name, robot_filters = bridge_filters(robot_bridge_cfg)
        cloud_name, cloud_filters = bridge_filters(cloud_bridge_cfg)
        self.sides = ((robot_name, MasterReader(robot_master_uri, robot_netns, enter), robot_filters),
                      (cloud_name, MasterReader(cloud_master_uri, cloud_netns, enter), cloud_filters))
        self.interval = interval
        self.uri_refresh = 1.0           # s between fresh lookups of every node's URI
        self._known: Dict[str, Dict[str, str]] = {}
        self._known_at = -float('inf')
        self._lock = threading.Lock()
        self._samples: List[Tuple[float, List[str]]] = []     # (check_at's time, violations)
        self._began: List[float] = []
        self._ended: List[float] = []
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.errors = 0

    def check_now(self) -> Tuple[float, List[str]]:
        """One check of the invariant: (its time, :func:`check_at`; what is wrong, empty when it holds). A master
        that does not answer is a violation, at the time the check gave up."""
        if time.monotonic() - self._known_at > self.uri_refresh:
            self._known, self._known_at = {}, time.monotonic()
        try:
            return check_at(*self.sides, known=self._known)
        except (OSError, RuntimeError, xmlrpc.client.Error, http.client.HTTPException) as exc:
            self.errors += 1
            return time.monotonic(), [f'a master did not answer: {exc}']

    def start(self) -> 'RestoreWatch':
        self._thread = threading.Thread(target=self._run, name='restore-watch', daemon=True)
        self._thread.start()
        return self

    def stop(self) -> 'RestoreWatch':
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            started = time.monotonic()
            sample = self.check_now()
            with self._lock:
                self._samples.append(sample)
            self._stop.wait(max(0.0, started + self.interval - time.monotonic()))

    def outage_began(self, t: Optional[float] = None) -> None:
        """An outage began at ``t`` (default now): it ends the previous outage's window."""
        with self._lock:
            self._began.append(time.monotonic() if t is None else t)

    def outage_ended(self, t: Optional[float] = None) -> None:
        """The link returned at ``t`` (default now)."""
        with self._lock:
            self._ended.append(time.monotonic() if t is None else t)

    def holds(self) -> bool:
        """Whether the last poll found the invariant holding."""
        with self._lock:
            return bool(self._samples) and not self._samples[-1][1]

    def restored_since(self, t: float) -> Optional[float]:
        """Seconds from ``t`` to the first poll of the current unbroken run of holding polls, if the last poll
        held and that run started after ``t`` began to be watched (None otherwise)."""
        with self._lock:
            samples = list(self._samples)
        return _at_poll_resolution(samples, t, math.inf, restore.unbroken_restore(samples, t))

    def problems(self) -> List[str]:
        with self._lock:
            return list(self._samples[-1][1]) if self._samples else ['not polled yet']

    def changes(self) -> List[Tuple[float, List[str]]]:
        """Every poll whose violations differ from the poll before (the first one too), each with the poll before
        it (:func:`multimaster_bridge.core.restore.changes`): (time, violations), in time order; what a later
        analysis needs to judge the registrations across by any other criterion, to one poll."""
        with self._lock:
            return changes(list(self._samples))

    def results(self) -> RestoreResults:
        """Per outage ended: the restore time within its window (up to the next outage's begin or now)."""
        with self._lock:
            return restore_times(list(self._samples), list(self._began), list(self._ended))


def restore_times(samples: List[Tuple[float, List[str]]], began: List[float], ended: List[float]) -> RestoreResults:
    """Per link return in ``ended``: the two measures of :mod:`multimaster_bridge.core.restore` within its window,
    which lasts until the next outage in ``began`` (or the last sample). ``samples``: (time, discrepancies) of every
    poll, in time order. A poll's time is when both masters had answered (:func:`check_at`), so neither measure is
    below the first poll after the return (the watch's resolution)."""
    out = RestoreResults()
    for t in ended:
        window_end = min((b for b in began if b >= t), default=math.inf)
        window = [s for s in samples if t <= s[0] < window_end]
        out.restores.append(_at_poll_resolution(samples, t, window_end,
                                                restore.unbroken_restore(samples, t, window_end)))
        out.lags.append(_at_poll_resolution(samples, t, window_end,
                                            restore.discrepancy_restore(samples, t, window_end)[0]))
        out.last_problems.append(next((w for _, w in reversed(window) if w), []))
    return out


def _at_poll_resolution(samples: List[Tuple[float, List[str]]], t: float, window_end: float,
                        measure: Optional[float]) -> Optional[float]:
    """``measure`` of the return at ``t``, never below the first poll after ``t`` (a poll's time is when both masters
    had answered); None without one before ``window_end``."""
    first = next((s[0] for s in samples if t <= s[0] < window_end), None)
    return None if measure is None or first is None else max(measure, first - t)


changes = restore.changes


__all__ = ['MasterReader', 'RestoreResults', 'RestoreWatch', 'bridge_filters', 'changes', 'check_at',
           'restore_times']
