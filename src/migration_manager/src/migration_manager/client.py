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
until the name resolves to another provider, within the call's timeout; if it never moves within it, the call
fails and the next one asks the same provider again (an instance whose lease lapsed and came back keeps its
address). The robot never
waits on the cloud: every call returns within its timeout.
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
        """One request, within ``timeout`` wall s in all.

        Returns:
            ``(ok, result, sent)``: ok is False for an exception (then ``result``), a timeout, a refusal
            (:func:`refused`; the answer in ``result``) or no provider within the timeout; ``sent`` is the wall time
            the request went out (after waiting for the name to move), or when the call gave up without one.
        """
        deadline = time.monotonic() + timeout
        if self.proxy is None:
            problem = self._wait_for_provider(deadline)
            if problem is not None:
                return False, problem, time.time()
            self.proxy = rospy.ServiceProxy(self.name, self.service_class, persistent=True)
        sent = time.time()
        done, result = call_with_timeout(self.proxy, max(0.0, deadline - time.monotonic()), *args)
        if done and not refused(result):
            self.avoid = None
            return True, result, sent
        proxy, self.proxy = self.proxy, None
        self.avoid = proxy.uri              # set by the lookup the call made (None: not even looked up)
        proxy.close()
        return False, result, sent

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
        """Wait until the name resolves to a provider other than the one to avoid (None), or the deadline: then
        the one to avoid is asked again (None) if it is still the provider, else an exception saying why not."""
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
