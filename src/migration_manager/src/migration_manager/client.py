"""The consumer side of migrations: a client of a movable module's service that follows it to its new host.

A movable module's service (``/global_goal_manager/next_goal``, the store's ``get_*`` services) keeps its name
across a migration, but its provider changes: the frozen instance answers "not the active instance"
(:data:`NOT_ACTIVE`) until it unregisters, and the master resolves the name to the new instance only once that
has registered it (on the robot, to a cloud instance: once the bridge has mirrored it). A client that simply
looks the name up again after a refusal finds the old provider for a while and asks it again: over a 100 ms
link a new connection to it costs three round trips (TCP, header, request) before it fails
(``bench_migration.sh``: a global_goal_manager hand-over to the robot at 100 ms that way spends 0.2–0.3 s
of its 0.25 s).

:class:`MovableServiceProxy` keeps one persistent connection; after a refusal or a failure it does not ask that
provider again until the name has moved: it polls its own master (local, cheap) every :data:`LOOKUP_POLL` s
until the name resolves to another provider and asks that one, within the call's timeout; if the name never
moves within it, the call fails and the next one asks the same provider again (an instance whose lease lapsed
and came back keeps its address). A kept connection that broke is made again once before its provider is
avoided. A request that stays unanswered longer than the provider usually takes is *hedged*: the name is
looked up and, if it has moved, the new provider is asked too (an instance being stopped after a hand-over
leaves a request on its kept connection unanswered until its process has gone). Safe because at most one
instance is active: only it serves, the others refuse. The robot never waits on the cloud: every call returns
within its timeout.
"""
from __future__ import annotations

import statistics
import threading
import time
from collections import deque
from typing import Any, Deque, Optional, Tuple

import rosgraph
import rospy

from cnr_runtime import BackgroundCall

NOT_ACTIVE = 'not the active instance'     # how a managed instance that is not active refuses a request
LOOKUP_POLL = 0.02                         # s between two lookups while the name has not moved yet
HEDGE_AFTER = 0.05                         # s a request stays unanswered at least before the name is looked up
ANSWER_TIMES = 5                           # recent answer times the hedge delay is the median of
HEDGE_POLL = 0.05                          # s between two lookups while a request stays unanswered


def refused(result: Any) -> bool:
    """A service's answer or exception that says the instance asked is not the active one."""
    if isinstance(result, Exception):
        return NOT_ACTIVE in str(result)
    return getattr(result, 'success', True) is False and str(getattr(result, 'message', '')).startswith(NOT_ACTIVE)


class MovableServiceProxy:
    """A persistent connection to ``name`` (type ``service_class``) that follows the service across migrations.

    Not thread-safe: one caller thread.
    """

    def __init__(self, name: str, service_class: Any) -> None:
        self.name = rospy.names.resolve_name(name)
        self.service_class = service_class
        self.proxy: Optional[rospy.ServiceProxy] = None
        self.avoid: Optional[str] = None    # the provider that refused or failed last: asked again only if the name stays
        self.answer_times: Deque[float] = deque(maxlen=ANSWER_TIMES)   # [s] the kept provider's recent answers
        self.master = rosgraph.Master(rospy.names.get_caller_id())

    def call(self, timeout: float, *args: Any) -> Tuple[bool, Any, float]:
        """One answer from an active provider, within ``timeout`` wall s in all: after a refusal or a failure the
        call waits for the name to move and asks the new provider (a request during a hand-over reaches the new
        instance, not a refusal); a provider that refused is not asked again within the call. A request that
        stays unanswered longer than usual is hedged (:meth:`_ask`).

        Returns:
            ``(ok, result, sent)``: ok is False when no provider answered within the timeout: ``result`` is then
            the last refusal (:func:`refused`) or exception (a timeout: ``TimeoutError``), or why no provider was
            asked; ``sent`` is the wall time the answered (or last) request went out (after waiting for the name
            to move), or when the call gave up without one.
        """
        deadline = time.monotonic() + timeout
        result: Any = None
        sent = time.time()
        while True:
            kept = self.proxy is not None   # a connection made by an earlier call
            if not kept:
                problem = self._wait_for_provider(deadline)
                if problem is not None:
                    return False, (problem if result is None else result), (time.time() if result is None else sent)
                self._keep(rospy.ServiceProxy(self.name, self.service_class, persistent=True))
            first = self.proxy
            done, result, sent, proxy = self._ask(deadline, args)
            if done and not refused(result):
                self.avoid = None
                self._keep(proxy)
                return True, result, sent
            self.proxy = None
            proxy.close()
            if isinstance(result, TimeoutError):
                self.avoid = proxy.uri
                return False, result, sent
            # a kept connection that broke is looked up and made again before its provider is avoided (the
            # provider may be the same, e.g. the other end dropped an idle connection); a refusal, or a fresh
            # connection that fails, is not asked again until the name moves
            stale = kept and proxy is first and not done and not refused(result)
            self.avoid = None if stale else proxy.uri   # (set by the lookup the call made; None: not looked up)

    def _keep(self, proxy: rospy.ServiceProxy) -> None:
        """Make ``proxy`` the kept connection (a new provider: its answer times are not known yet)."""
        if proxy is not self.proxy:
            if self.proxy is not None:
                self.proxy.close()
            if self.proxy is None or proxy.uri != self.proxy.uri:
                self.answer_times.clear()
            self.proxy = proxy

    def _hedge_delay(self) -> float:
        """How long a request may go unanswered before the name is looked up: twice the median of the provider's
        recent answer times, at least :data:`HEDGE_AFTER`."""
        return max(HEDGE_AFTER, 2.0 * statistics.median(self.answer_times)) if self.answer_times else HEDGE_AFTER

    def _ask(self, deadline: float, args: Tuple[Any, ...]) -> Tuple[bool, Any, float, rospy.ServiceProxy]:
        """Ask the kept provider, hedged: while it has not answered for :meth:`_hedge_delay`, the name is looked up
        every :data:`HEDGE_POLL` s, and once it has moved to another provider that one is asked too; the first
        answer that is not a refusal wins (at most one instance is active: both cannot serve). The request a
        provider that is being stopped took in was left unanswered until its process had gone: 0.13-0.7 s on
        the capped robot (``bench_migration.sh``, global_goal_manager hand-overs to the cloud).

        Returns:
            ``(done, result, sent, proxy)`` of the winning request, else of the latest one that ended (a
            refusal or a failure), else ``(False, TimeoutError, sent, kept proxy)`` at the deadline.
        """
        wake = threading.Event()
        attempts = [BackgroundCall(self.proxy, *args, wake=wake)]
        hedge_at = time.monotonic() + self._hedge_delay()
        ended: Optional[BackgroundCall] = None
        while True:
            wake.clear()
            for attempt in attempts:
                if attempt.finished.is_set():
                    if attempt.done and not refused(attempt.result):
                        for other in attempts:
                            if other is not attempt:
                                other.func.close()      # (an unanswered request there is abandoned)
                        if attempt.func is self.proxy:
                            self.answer_times.append(attempt.took)
                        return True, attempt.result, attempt.sent, attempt.func
                    ended = attempt
            if all(a.finished.is_set() for a in attempts):
                for other in attempts:
                    if other is not ended:
                        other.func.close()
                return ended.done, ended.result, ended.sent, ended.func
            now = time.monotonic()
            if now >= deadline:
                for other in attempts[1:]:
                    other.func.close()
                first = attempts[0]
                return False, TimeoutError(f'no answer within {deadline - first.started:.3g} s'), first.sent, first.func
            if len(attempts) == 1 and now >= hedge_at:
                uri = self._lookup()
                asked = attempts[0].func.uri
                if uri is not None and asked is not None and uri != asked and uri != self.avoid:
                    hedge = rospy.ServiceProxy(self.name, self.service_class, persistent=True)
                    attempts.append(BackgroundCall(hedge, *args, wake=wake))
                hedge_at = now + HEDGE_POLL
            wake.wait(max(0.0, min(deadline, hedge_at if len(attempts) == 1 else deadline) - now))

    def close(self) -> None:
        if self.proxy is not None:
            self.proxy.close()
            self.proxy = None

    def _lookup(self) -> Optional[str]:
        try:
            return self.master.lookupService(self.name)
        except Exception:                   # not registered (MasterError) or the master unreachable: not yet
            return None

    def _wait_for_provider(self, deadline: float) -> Optional[Exception]:
        """Wait until the name resolves to a provider other than the one to avoid (returns None) or the deadline
        (returns an exception saying why not; a provider that still holds the name is then no longer avoided: the
        next call asks it again)."""
        while True:
            uri = self._lookup()
            if uri is not None and uri != self.avoid:
                return None
            if time.monotonic() + LOOKUP_POLL >= deadline:
                if uri is not None:         # the name never moved: the same provider, asked again next time
                    self.avoid = None
                    return rospy.ServiceException(f'{self.name}: only the provider that refused ({uri}) within '
                                                  f'the timeout')
                return rospy.ServiceException(f'service [{self.name}] unavailable')
            if rospy.core.is_shutdown_requested():
                return rospy.ServiceException('shutting down')
            time.sleep(LOOKUP_POLL)
