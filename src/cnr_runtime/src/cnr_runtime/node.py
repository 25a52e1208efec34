"""The rospy process runtime of every node: :func:`init_node` (signals and exception hooks off the main thread),
:func:`quiet_at_shutdown`, the per-host caller id of a module instance (:func:`distinct_callerid`), and
:class:`BackgroundCall` / :func:`call_with_timeout` (the robot never waits on the cloud)."""
from __future__ import annotations

import os
import threading
import time

import rospy


# set (to the host's name) in the environment of a module instance that migration_manager may move: the instance
# announces "<node name>@<host>" in its TCPROS headers from its very first connection (see distinct_callerid)
CALLERID_SUFFIX_ENV = 'CNR_CALLERID_SUFFIX'


def distinct_callerid(suffix: str) -> None:
    """Make this process announce ``<node name>@<suffix>`` as its caller id in its TCPROS connection headers
    (subscriptions and publications); registrations with the master keep the node's real name.

    Two instances of a module (one per host, managed by migration_manager) share the node name, so that topics,
    services and parameters keep their names across a migration. A rospy publisher keeps one connection per
    subscriber caller id and drops the older one when a second arrives (``_TopicImpl.add_connection``): without
    this, a standby's subscription silently cuts the active instance off from every publisher both subscribe to
    (its inputs, the lease answers, and ``/clock``, which ``rospy.init_node`` subscribes: an instance that lost
    it stands still in sim time). Publications say the same name, so that a peer matching the two (actionlib's
    ``wait_for_server`` checks that its goal publisher is connected to the caller id in the server's status
    messages) still finds them. Idempotent.
    """
    from rospy.impl import tcpros_pubsub
    for cls in (tcpros_pubsub.TCPROSSub, tcpros_pubsub.TCPROSPub):
        original = cls.get_header_fields
        if getattr(original, '_cnr_instance_suffix', None) is not None:
            continue

        def get_header_fields(self, _original=original):
            fields = _original(self)
            fields['callerid'] = f"{fields['callerid']}@{suffix}"
            return fields
        get_header_fields._cnr_instance_suffix = suffix
        cls.get_header_fields = get_header_fields


def init_node(name: str, **kwargs) -> None:
    """``rospy.init_node`` with SIGINT/SIGTERM handled off the main thread; every node of the workspace uses it.

    rospy's own handler runs the shutdown (unregistering from the master) inside the signal handler, on the
    main thread. If the signal lands while that thread is in a master call, rospy's master proxy lock is
    already held and the node deadlocks until SIGKILL (seen with move_base stopped during its start-up over a
    slow link), and the simulator, interrupted while publishing under its own lock, needed roslaunch's SIGKILL.
    Here the handler only starts a thread that calls ``rospy.signal_shutdown``, so every node stops on
    SIGINT within a loop period (tests/test_launch_lifecycle.py).

    While that shutdown closes the node's topics, any thread (a loop, a ``rospy.Timer``) may be in the middle
    of a ``publish()`` or a ``rospy.sleep()`` and get ``ROSException``/``ROSInterruptException``: expected,
    not an error. Such an exception, raised once the shutdown has begun, ends its thread quietly instead of
    printing a traceback; every other exception is reported as before.
    """
    import signal
    import sys
    import threading
    suffix = os.environ.get(CALLERID_SUFFIX_ENV, '')
    if suffix:                           # before init_node: its /clock subscription must carry it too
        distinct_callerid(suffix)
    rospy.init_node(name, disable_signals=True, **kwargs)

    def expected_at_shutdown(exc_type) -> bool:
        return (exc_type is not None and issubclass(exc_type, rospy.ROSException)
                and rospy.core.is_shutdown_requested())

    default_thread_hook, default_hook = threading.excepthook, sys.excepthook

    def thread_hook(args) -> None:
        if not expected_at_shutdown(args.exc_type):
            default_thread_hook(args)

    def main_hook(exc_type, exc, tb) -> None:
        if not expected_at_shutdown(exc_type):
            default_hook(exc_type, exc, tb)

    threading.excepthook = thread_hook
    sys.excepthook = main_hook

    def handler(signum, _frame) -> None:
        threading.Thread(target=rospy.signal_shutdown, args=(f'signal {signum}',), daemon=True).start()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def quiet_at_shutdown(callback):
    """Wrap a callback that rospy calls and guards itself (a subscriber callback, a service handler, an
    actionlib execute callback) so that a ``ROSException`` raised once the shutdown has begun (a publish onto a
    topic the shutdown already closed) ends it quietly. rospy and actionlib would log such an exception with
    its traceback; :func:`init_node` already does this for exceptions that end a thread. Anything else, or
    the same exception before the shutdown, propagates as before."""
    import functools

    @functools.wraps(callback)
    def wrapper(*args, **kwargs):
        try:
            return callback(*args, **kwargs)
        except rospy.ROSException:
            if rospy.core.is_shutdown_requested():
                return None
            raise
    return wrapper


class BackgroundCall:
    """``func(*args, **kwargs)`` running in a daemon thread of its own (rospy's service calls have no timeout:
    a call that overruns is abandoned, not interrupted; its thread ends when rospy gives up on the connection).
    ``func`` is what it calls. ``finished`` is set, and ``wake`` (if given) too, once it has returned: ``done`` True and ``result`` its
    value, or ``done`` False and ``result`` the exception it raised. ``sent`` (wall) and ``started`` (monotonic)
    say when it began, ``took`` how long it ran [s]."""

    def __init__(self, func, *args, wake=None, **kwargs) -> None:
        self.func = func
        self.done = False
        self.result = None
        self.took = 0.0
        self.finished = threading.Event()
        self.sent, self.started = time.time(), time.monotonic()
        self._wake = wake
        threading.Thread(target=self._run, args=(args, kwargs), name='background_call', daemon=True).start()

    def _run(self, args, kwargs) -> None:
        try:
            self.result = self.func(*args, **kwargs)
            self.done = True
        except Exception as exc:          # reported to the caller, who decides
            self.result = exc
        self.took = time.monotonic() - self.started
        self.finished.set()
        if self._wake is not None:
            self._wake.set()


def call_with_timeout(func, timeout: float, *args, **kwargs):
    """Call ``func(*args, **kwargs)`` (e.g. a ``rospy.ServiceProxy`` to a module on another host), giving up
    after ``timeout`` wall seconds: the robot never waits on the cloud. The call runs as a
    :class:`BackgroundCall`; one that overruns is abandoned.

    Returns:
        ``(True, result)``, or ``(False, exception)`` for an exception or ``TimeoutError`` on a timeout.
    """
    call = BackgroundCall(func, *args, **kwargs)
    if not call.finished.wait(timeout):
        return False, TimeoutError(f'no answer within {timeout:g} s')
    return call.done, call.result
