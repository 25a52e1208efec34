"""migration_manager.client.MovableServiceProxy against a real rosmaster and real providers (TCPROS).

Two provider processes register the same service name, as two instances of a movable module do across a
migration: one refuses (not the active instance), the other serves. Within one call the client must not ask the
refusing provider again while the name still points at it, must be answered by the new provider once that
registers, and when the name never moves its next call must ask the old one again (a lapsed lease that came
back). A request the old provider takes and never answers (an instance being stopped) is hedged to the provider
the name moved to."""
from __future__ import annotations

import sys
import threading
import time

import pytest

pytest.importorskip('rospy')

from cnr_harness import wait_until  # noqa: E402

NAME = '/movable_test/next_goal'

PROVIDER = r'''
import sys, rospy
from cnr_msgs.srv import NextGoal, NextGoalResponse
from migration_manager.client import NOT_ACTIVE
who, mode = sys.argv[1], sys.argv[2]
rospy.init_node(who)
count = 0
def handle(req):
    global count
    count += 1
    print(f"request {count}", flush=True)
    if mode == "refuse":
        return NextGoalResponse(success=False, message=f"{NOT_ACTIVE} (frozen)", policy=who)
    return NextGoalResponse(success=True, message="served", policy=who)
rospy.Service(sys.argv[3], NextGoal, handle)
print("ready", flush=True)
rospy.spin()
'''


def requests(proc) -> int:
    return proc.output().count('request ')


def provider(ros, who: str, mode: str):
    proc = ros.master.run([sys.executable, '-c', PROVIDER, who, mode, NAME], log_name=who)
    wait_until(lambda: 'ready' in proc.output(), 30.0, f'{who} registered', proc)
    return proc


def lookup(ros) -> str:
    try:
        return ros.master.call('lookupService', NAME)
    except RuntimeError:
        return ''


def test_a_refusing_provider_is_not_asked_again_until_the_name_moves(ros):
    from cnr_msgs.srv import NextGoal
    from migration_manager.client import MovableServiceProxy
    old = provider(ros, 'provider_old', 'refuse')
    new = None
    client = MovableServiceProxy(NAME, NextGoal)
    try:
        # one call: the old provider refuses, the call waits for the name to move (not asking it again) ...
        box = {}
        caller = threading.Thread(target=lambda: box.update(result=client.call(10.0, 0.0, 0.0)))
        caller.start()
        wait_until(lambda: requests(old) == 1, 10.0, 'the request at the old provider', old)
        time.sleep(0.5)               # (not synchronisation: the time the old provider would have been asked in)
        assert requests(old) == 1, 'the provider that refused was asked again while the name still pointed at it'
        assert caller.is_alive(), f'the call did not wait for the name to move: {box}'
        # ... and is answered by the new provider as soon as that holds the name
        new = provider(ros, 'provider_new', 'serve')
        caller.join(10.0)
        ok, answer, sent = box['result']
        assert ok and answer.policy == 'provider_new', answer
        assert requests(old) == 1 and requests(new) == 1
        assert sent <= time.time()
        ok, answer, _ = client.call(5.0, 0.0, 0.0)        # the connection to it is kept
        assert ok and answer.policy == 'provider_new' and requests(new) == 2
    finally:
        client.close()
        for proc in (new, old):
            if proc is not None:
                ros.master.stop_child(proc)
    wait_until(lambda: not lookup(ros), 10.0, 'the providers unregistered')


def test_a_name_that_never_moves_is_asked_again_by_the_next_call(ros):
    from cnr_msgs.srv import NextGoal
    from migration_manager.client import MovableServiceProxy
    old = provider(ros, 'provider_lapsed', 'refuse')
    client = MovableServiceProxy(NAME, NextGoal)
    try:
        ok, answer, _ = client.call(0.3, 0.0, 0.0)        # refused, then no other provider within 0.3 s
        assert not ok and answer.policy == 'provider_lapsed', answer
        assert requests(old) == 1, 'asked twice in one call'
        ok, answer, _ = client.call(0.3, 0.0, 0.0)        # the next call asks it again (a lease that came back)
        assert not ok and answer.policy == 'provider_lapsed', answer
        assert requests(old) == 2
    finally:
        client.close()
        ros.master.stop_child(old)
    ok, answer, _ = client.call(0.3, 0.0, 0.0)            # no provider at all: unavailable within the timeout
    assert not ok and 'unavailable' in str(answer), answer


def test_a_kept_connection_to_a_provider_that_went_away_is_made_again_within_the_call(ros):
    from cnr_msgs.srv import NextGoal
    from migration_manager.client import MovableServiceProxy
    first = provider(ros, 'provider_first', 'serve')
    client = MovableServiceProxy(NAME, NextGoal)
    second = None
    try:
        ok, answer, _ = client.call(5.0, 0.0, 0.0)
        assert ok and answer.policy == 'provider_first'
        ros.master.stop_child(first)                       # its kept connection breaks
        first = None
        second = provider(ros, 'provider_second', 'serve')
        ok, answer, _ = client.call(5.0, 0.0, 0.0)
        assert ok and answer.policy == 'provider_second', answer
    finally:
        client.close()
        for proc in (first, second):
            if proc is not None:
                ros.master.stop_child(proc)


HANGING = r'''
import sys, threading, rospy
from cnr_msgs.srv import NextGoal, NextGoalResponse
who = sys.argv[1]
rospy.init_node(who)
count = 0
never = threading.Event()
def handle(req):
    global count
    count += 1
    print(f"request {count}", flush=True)
    if count > 1:                        # as an instance being stopped: takes the request, never answers
        never.wait()
    return NextGoalResponse(success=True, message="served", policy=who)
rospy.Service(sys.argv[2], NextGoal, handle)
print("ready", flush=True)
rospy.spin()
'''


def test_an_unanswered_request_is_hedged_to_the_provider_the_name_moved_to(ros):
    """The old provider takes the request and never answers (an instance being stopped after a hand-over, on the
    capped robot, for up to 0.7 s): once the name has moved, the new provider is asked within the same call."""
    from cnr_msgs.srv import NextGoal
    from migration_manager.client import MovableServiceProxy
    old = ros.master.run([sys.executable, '-c', HANGING, 'provider_hanging', NAME], log_name='provider_hanging')
    wait_until(lambda: 'ready' in old.output(), 30.0, 'provider_hanging registered', old)
    new = None
    client = MovableServiceProxy(NAME, NextGoal)
    try:
        ok, answer, _ = client.call(5.0, 0.0, 0.0)
        assert ok and answer.policy == 'provider_hanging'
        box = {}
        caller = threading.Thread(target=lambda: box.update(result=client.call(30.0, 0.0, 0.0)))
        caller.start()
        wait_until(lambda: requests(old) == 2, 10.0, 'the second request at the old provider', old)
        moved = time.time()
        new = provider(ros, 'provider_taking_over', 'serve')
        caller.join(30.0)
        ok, answer, sent = box['result']
        assert ok and answer.policy == 'provider_taking_over', answer     # not a timeout after 30 s
        assert sent >= moved and requests(new) == 1
        ok, answer, _ = client.call(5.0, 0.0, 0.0)        # and the connection to the new provider is kept
        assert ok and answer.policy == 'provider_taking_over' and requests(new) == 2
        assert requests(old) == 2
    finally:
        client.close()
        for proc in (new, old):
            if proc is not None:
                ros.master.stop_child(proc)
