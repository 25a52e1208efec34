"""The consumer side of migrations: a client of a movable module's service that follows it to its new host.

A movable module's service (``/global_goal_manager/next_goal``, the store's ``get_*`` services) keeps its name
across a migration, but its provider changes: the frozen instance answers "not the active instance"
(:data:`NOT_ACTIVE`) until it unregisters, and the master resolves the name to the new instance only once that
has registered it (on the robot, to a cloud instance: once the bridge has mirrored it). A client that simply
looks the name up again after a refusal finds the old provider for a while and asks it again: over a 100 ms
link a new connection to it costs three round trips (TCP, header, request) before it fails
(``bench_migration.sh`` session 23: every global_goal_manager hand-over to the robot at 100 ms that took over
0.25 s spent 0.2–0.3 s that way).

:class:`MovableServiceProxy` keeps one persistent connection; after a refusal or a failure it does not ask that
provider again until the name has moved: it polls its own master (local, cheap) every :data:`LOOKUP_POLL` s
until the name resolves to another provider and asks that one, within the call's timeout; if the name never
moves within it, the call fails and the next one asks the same provider again (an instance whose lease lapsed
and came back keeps its address). A kept connection that broke is made again once before its provider is
avoided. The robot never waits on the cloud: every call returns within its timeout.
"""
from __future__ import annotations

import time
from typing import Any, Optional, Tuple

import rosgraph
import rospy

from cnr_params.ros import call_with_timeout

NOT_ACTIVE = 'not the active instance'     # how a managed instance that is not active refuses a request
LOOKUP_POLL = 0.02                         # s between two lookups while the name has not moved yet


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
        self.master = rosgraph.Master(rospy.names.get_caller_id())

    def call(self, timeout: float, *args: Any) -> Tuple[bool, Any, float]:
        """One answer from an active provider, within ``timeout`` wall s in all: after a refusal or a failure the
        call waits for the name to move and asks the new provider (a request during a hand-over reaches the new
        instance, not a refusal); a provider that refused is not asked again within the call.

        Returns:
            ``(ok, result, sent)``: ok is False when no provider answered within the timeout: ``result`` is then
            the last refusal (:func:`refused`) or exception (a timeout: ``TimeoutError``), or why no provider was
            asked; ``sent`` is the wall time the last request went out (after waiting for the name to move), or
            when the call gave up without one.
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
                self.proxy = rospy.ServiceProxy(self.name, self.service_class, persistent=True)
            sent = time.time()
            done, result = call_with_timeout(self.proxy, max(0.0, deadline - time.monotonic()), *args)
            if done and not refused(result):
                self.avoid = None
                return True, result, sent
            proxy, self.proxy = self.proxy, None
            proxy.close()
            if isinstance(result, TimeoutError):
                self.avoid = proxy.uri
                return False, result, sent
            # a kept connection that broke is looked up and made again before its provider is avoided (the
            # provider may be the same, e.g. the other end dropped an idle connection); a refusal, or a fresh
            # connection that fails, is not asked again until the name moves
            stale = kept and not done and not refused(result)
            self.avoid = None if stale else proxy.uri   # (set by the lookup the call made; None: not looked up)

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
