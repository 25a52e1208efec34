"""move_base's action server: actionlib's SimpleActionServer that can take over goals another instance accepted.

A migrated move_base must continue the client's goal under the *same* goal id: actionlib's ActionClient marks
its goal LOST as soon as a status array arrives without it (``CommStateMachine.update_status``), and calls a
status of PENDING after ACTIVE an invalid transition. :meth:`TakeoverActionServer.start_with` therefore starts
the server with the handed-over goals already in its status list, in the status the client last saw (ACTIVE,
or PREEMPTING if a cancel was requested), before the first status array is published, and the execute thread
runs such a goal without accepting it a second time. :meth:`TakeoverActionServer.release` closes the server
for good (frozen for a migration): no terminal status for the goal, which belongs to the next instance now.

Goals and cancels sent while no instance is active (between the freeze of one and the start of the next) would
reach nobody: actionlib sends a goal once, and its client then waits for an acknowledgement until its own
timeout. A prepared server that is not started therefore *parks* what it receives (the newest
:data:`PARKED`), and every started server remembers the goal ids and cancels it received (the newest
:data:`SEEN`, carried on from instance to instance in the hand-over). :meth:`TakeoverActionServer.start_with`
replays, after the handed-over goals and in arrival order, what it parked that neither it nor the instances
before it received: exactly what was sent in the gap.

Lock order as actionlib: ``action_server.lock`` before ``self.lock``.
"""
from __future__ import annotations

import traceback
from collections import deque
from typing import Deque, Iterable, List, Optional, Sequence, Tuple

import actionlib
import rosgraph
import rospy
from actionlib.server_goal_handle import ServerGoalHandle
from actionlib_msgs.msg import GoalID, GoalStatus

TAKEN_OVER = 'This goal was taken over from the previous move_base instance'
PARKED = 16          # goals and cancels a prepared, not started server keeps (the newest)
SEEN = 64            # goal ids and cancels a started server remembers (the newest); > PARKED, so a parked
                     # message any instance before received is known to have been received
CancelKey = Tuple[str, int, int]      # a cancel request: goal id ('' = all), stamp secs, nsecs


def cancels(cancel: GoalID, goal: GoalID) -> bool:
    """Does ``cancel`` apply to ``goal``? actionlib's rule (``ActionServer.internal_cancel_callback``): every goal
    if its id is empty and its stamp zero, the goal of its id, and every goal stamped at or before a non-zero
    stamp."""
    zero = rospy.Time()
    return ((not cancel.id and cancel.stamp == zero) or cancel.id == goal.id
            or (cancel.stamp != zero and goal.stamp <= cancel.stamp))


class TakeoverActionServer(actionlib.SimpleActionServer):
    """SimpleActionServer (never auto-started) with :meth:`start_with` and :meth:`release`."""

    EXECUTE_POLL = 0.1     # [s] the execute thread looks for a goal at least this often (actionlib's loop_duration)

    def __init__(self, name: str, action_spec, execute_cb) -> None:
        self._adopted: Optional[ServerGoalHandle] = None
        self._prepared = False
        self._connected = False             # clients_connected() held once
        self._parked: Deque[Tuple[str, object]] = deque(maxlen=PARKED)      # ('goal' | 'cancel', message)
        self._seen_goals: Deque[str] = deque(maxlen=SEEN)
        self._seen_cancels: Deque[CancelKey] = deque(maxlen=SEEN)
        super().__init__(name, action_spec, execute_cb=execute_cb, auto_start=False)
        a = self.action_server              # its subscribers (made in initialize()) call these
        a.internal_goal_callback = self._on_goal
        a.internal_cancel_callback = self._on_cancel

    @staticmethod
    def _cancel_key(goal_id: GoalID) -> CancelKey:
        return goal_id.id, goal_id.stamp.secs, goal_id.stamp.nsecs

    def _on_goal(self, action_goal) -> None:
        a = self.action_server
        with a.lock:
            if a.started:
                self._seen_goals.append(action_goal.goal_id.id)
                type(a).internal_goal_callback(a, action_goal)
            elif self._prepared:
                self._parked.append(('goal', action_goal))

    def _on_cancel(self, goal_id: GoalID) -> None:
        a = self.action_server
        with a.lock:
            if a.started:
                self._seen_cancels.append(self._cancel_key(goal_id))
                type(a).internal_cancel_callback(a, goal_id)
            elif self._prepared:
                self._parked.append(('cancel', goal_id))

    def seen(self) -> Tuple[List[str], List[CancelKey]]:
        """The goal ids and cancels this server received while started (and those it was handed), oldest
        first: the hand-over's ``seen_goals`` and ``seen_cancels``."""
        with self.action_server.lock:
            return list(self._seen_goals), list(self._seen_cancels)

    def prepare(self) -> None:
        """Create the action's publishers, subscribers and status timer now, without starting the server: a
        standby does this ahead of its promotion (their registrations with the master and the connections take
        ≈ 1 s on the capped robot). Until :meth:`start_with`, goals and cancels are parked, not acted on, and no
        status goes out (actionlib's ``started`` flag), as after :meth:`release`."""
        a = self.action_server
        with a.lock, self.lock:
            if not self._prepared:
                a.initialize()
                self._prepared = True
                self._pause()

    def clients_connected(self) -> bool:
        """Are the goal and cancel subscribers connected to every publisher the master lists for their topics
        (the clients, this node itself, the other instance)? A clone promoted before its connections are up
        misses a goal sent at once (a cold bench: mfg's goal 0.3 s before the promotion of a clone just started
        on the capped robot reached neither instance). Asked of the master until it holds once, then true."""
        if self._connected:
            return True
        a = self.action_server
        if not self._prepared:
            return False
        try:
            publishers = dict(rosgraph.Master(rospy.get_name()).getSystemState()[0])
        except (rosgraph.MasterException, OSError):      # the master busy or gone: not known yet
            return False
        for sub in (a.goal_sub, a.cancel_sub):
            if sub.get_num_connections() < len(publishers.get(sub.resolved_name, ())):
                return False
        self._connected = True
        return True

    @property
    def started(self) -> bool:
        return bool(self.action_server.started)

    def executeLoop(self) -> None:
        """actionlib's execute thread without its lost wake-up. actionlib's looks for a new goal without a lock and
        then waits :attr:`EXECUTE_POLL`; a goal that arrives between the look and the wait is notified to nobody
        and waits for the timeout — and so does one that arrives while the execute callback returns: a goal
        taken over at a promotion could start up to 100 ms late. Here the look and the wait are under the
        execute condition's lock, which the goal callback holds while it sets the goal and notifies.

        And without actionlib's abort at the shutdown: a callback the node's shutdown ended leaves its goal
        active, and aborting it then publishes onto topics the shutdown closes ("publish() to a closed topic"
        with its traceback at a mission's end); the thread just ends."""
        while not rospy.is_shutdown():
            with self.terminate_mutex:
                if self.need_to_terminate:
                    break
            if self.is_active():
                rospy.logerr('Should never reach this code with an active goal')
                return
            with self.execute_condition:
                if not self.is_new_goal_available():
                    self.execute_condition.wait(self.EXECUTE_POLL)
                    continue
            goal = self.accept_new_goal()
            try:
                self.execute_callback(goal)
                if rospy.core.is_shutdown_requested():
                    break          # the shutdown ended the callback and closes the topics: no status can go out
                if self.is_active():
                    rospy.logwarn('Your executeCallback did not set the goal to a terminal status. This is a bug in '
                                  'your ActionServer implementation. Fix your code! For now, the ActionServer will '
                                  'set this goal to aborted')
                    self.set_aborted(None, 'No terminal state was set.')
            except Exception as exc:       # as actionlib: the goal aborted, the thread goes on
                if rospy.core.is_shutdown_requested():
                    break          # e.g. "publish() to a closed topic": the node is going
                rospy.logerr(f'Exception in your execute callback: {exc}\n{traceback.format_exc()}')
                self.set_aborted(None, f'Exception in execute callback: {exc}')

    def start_with(self, goals: Sequence[Tuple[object, str, bool]] = (),
                   seen_goals: Optional[Iterable[str]] = (), seen_cancels: Iterable[CancelKey] = ()) -> List[str]:
        """Start the server (as ``start()``) with goals taken over, then take up what was sent in the gap.

        Args:
            goals: ``(action_goal, status, cancel_requested)``, oldest first; ``action_goal`` is the action's
                ActionGoal message with the client's goal id, ``status`` 'active' (the goal being pursued: it
                is ACTIVE, or PREEMPTING if cancelled, in the first status array, and the execute callback runs
                it) or 'pending' (received, not accepted yet: PENDING, or RECALLING if cancelled; accepted as
                any new goal). A pending goal after an active one preempts it, as it would have in the
                instance that received it.
            seen_goals, seen_cancels: what the instances before this one received (the hand-over's): parked
                messages among them are not replayed. ``seen_goals`` None: not known (a state without it),
                nothing parked is replayed.

        Returns:
            what was replayed, for the log (``goal <id>`` / ``cancel <id or all>``).
        """
        a = self.action_server
        with a.lock, self.lock:
            if a.started:
                return
            if not self._prepared:  # publishers, subscribers, status timer: nothing is published before
                a.initialize()      # the publish_status() below
                self._prepared = True
            self._resume()
            a.started = True
            if seen_goals is None:                    # not known what the instances before received
                self._parked.clear()
                seen_goals = ()
            self._seen_goals.extend(seen_goals)
            self._seen_cancels.extend(tuple(c) for c in seen_cancels)
            for action_goal, status, cancel in goals:
                self._on_goal(action_goal)
                handle = self.next_goal
                if not (self.new_goal and handle.get_goal() and
                        handle.get_goal_id().id == action_goal.goal_id.id):
                    rospy.logwarn(f'move_base: goal {action_goal.goal_id.id} could not be taken over')
                    continue
                if status == 'active':
                    tracker = handle.status_tracker
                    tracker.status.status = GoalStatus.PREEMPTING if cancel else GoalStatus.ACTIVE
                    tracker.status.text = TAKEN_OVER
                    self.new_goal_preempt_request = cancel
                    self._adopted = handle
                elif cancel:
                    type(a).internal_cancel_callback(a, GoalID(id=action_goal.goal_id.id))
            replayed: List[str] = []
            taken: List[GoalID] = []                  # goals replayed here, in arrival order
            goals_known, cancels_known = set(self._seen_goals), set(self._seen_cancels)
            parked, self._parked = list(self._parked), deque(maxlen=PARKED)
            for kind, msg in parked:
                if kind == 'goal':
                    if msg.goal_id.id not in goals_known:    # sent while no instance was active, or lost to the
                        self._on_goal(msg)                   # one that was: nobody took it
                        taken.append(msg.goal_id)
                        replayed.append(f'goal {msg.goal_id.id}')
                elif self._cancel_key(msg) not in cancels_known:
                    self._on_cancel(msg)                     # as the instance before would have applied it
                    replayed.append(f'cancel {msg.id or "all"}')
                else:       # the instance before had this cancel but not a goal taken up above: it applies to it
                    for gid in taken:
                        if cancels(msg, gid):
                            type(a).internal_cancel_callback(a, GoalID(id=gid.id))
                            replayed.append(f'cancel {gid.id}')
            a.publish_status()
        return replayed

    def accept_new_goal(self):
        """As actionlib's, except for a goal taken over: it is already ACTIVE (or PREEMPTING) at the client."""
        with self.action_server.lock, self.lock:
            adopted, self._adopted = self._adopted, None
            if adopted is None or not self.new_goal or self.next_goal is not adopted:
                return super().accept_new_goal()
            self.current_goal = self.next_goal
            self.new_goal = False
            self.preempt_request = self.new_goal_preempt_request
            self.new_goal_preempt_request = False
            return self.current_goal.get_goal()

    def release(self) -> None:
        """Close the server and forget its goals without a terminal status (handed over to another instance):
        no more goals, cancels, status, feedback or results. Its publishers and subscribers stay, silent, as a
        prepared server's (no unregistering while the hand-over waits); :meth:`start_with` may open it again."""
        a = self.action_server
        with a.lock, self.lock:
            a.started = False           # goals and cancels parked, no status (actionlib's stop() would also
            a.status_list = []          # unregister everything: slow on the capped robot)
            self._pause()
            self.current_goal = ServerGoalHandle()
            self.next_goal = ServerGoalHandle()
            self.new_goal = self.preempt_request = self.new_goal_preempt_request = False
            self._adopted = None

    def _pause(self) -> None:
        """No status timer while the server is not started (prepared, released, a dormant instance's): it would
        only find the server closed, and a rospy.Timer on sim time wakes at every /clock message (a dormant
        move_base used 0.025 CPU). :meth:`_resume` starts it with the server. Call with ``action_server.lock``."""
        a = self.action_server
        if a.status_timer is not None:
            a.status_timer.shutdown()
            a.status_timer = None

    def _resume(self) -> None:
        a = self.action_server
        if a.status_timer is None and a.status_frequency > 0.0:
            a.status_timer = rospy.Timer(rospy.Duration(1.0 / a.status_frequency), a.publish_status_async)

    def goal_snapshot(self) -> Tuple[Optional[ServerGoalHandle], Optional[ServerGoalHandle]]:
        """(the goal being pursued, a newer goal not accepted yet), each None if there is none. Call with
        ``action_server.lock`` and ``self.lock`` held for a consistent pair."""
        current = self.current_goal if self.is_active() else None
        pending = self.next_goal if self.new_goal and self.next_goal.get_goal() else None
        if self._adopted is not None and pending is self._adopted:
            current, pending = pending, None          # taken over, the execute thread has not run it yet
        return current, pending
