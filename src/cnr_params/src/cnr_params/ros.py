"""Parameter-server side of :mod:`cnr_params`: read a node's private namespace as a :class:`Section`."""
from __future__ import annotations

import rospy

from cnr_params.config import Section


def private_section(namespace: str = '~') -> Section:
    """All parameters under ``namespace`` as one :class:`Section` (one getParam call).

    Errors name the resolved namespace, e.g. ``/simulator: laser.max_range: must be > 0``.
    """
    resolved = rospy.resolve_name(namespace)
    data = rospy.get_param(namespace, {})
    return Section(data if isinstance(data, dict) else {}, resolved.rstrip('/') or '/')


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


def call_with_timeout(func, timeout: float, *args, **kwargs):
    """Call ``func(*args, **kwargs)`` (e.g. a ``rospy.ServiceProxy`` to a module on another host), giving up
    after ``timeout`` wall seconds: the robot never waits on the cloud.

    rospy's service calls have no timeout of their own (a connection to an unreachable host can block for
    minutes), so the call runs in a daemon thread; a call that overruns is abandoned, not interrupted (its
    thread ends when rospy gives up on the connection).

    Returns:
        ``(True, result)``, or ``(False, exception)`` for an exception or ``TimeoutError`` on a timeout.
    """
    import threading
    box: dict = {}

    def run() -> None:
        try:
            box['result'] = func(*args, **kwargs)
        except Exception as exc:          # reported to the caller, who decides
            box['error'] = exc

    worker = threading.Thread(target=run, name='call_with_timeout', daemon=True)
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        return False, TimeoutError(f'no answer within {timeout:g} s')
    if 'error' in box:
        return False, box['error']
    return True, box['result']
