"""move_base movable by migration_manager: the adapter around a plain :class:`MoveBaseNode` (README "Migration
state") and the ``move_base`` executable's entry point.

As a managed standby the costmaps follow the sensors but the node has no action server, no services and
publishes nothing; on promotion the client's goal is taken over with its goal id
(:mod:`cnr_navigation.action_server`) and continues; frozen, the node stops commanding at once and leaves the
goal to the next instance without a terminal status; dormant, its inputs are closed too. The state handed over
is :mod:`cnr_navigation.core.migration`'s.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

import rospy
from actionlib_msgs.msg import GoalStatus
from move_base_msgs.msg import MoveBaseActionGoal

import cnr_params
from cnr_runtime import init_node
from cnr_navigation.core.geometry import yaw_to_quaternion
from cnr_navigation.core.migration import GoalRecord, HandOver, parse_state, target_yaw
from cnr_navigation.core.param_reader import read_navigation_params
from cnr_navigation.move_base_node import MoveBaseNode, Progress
from cnr_navigation.ros_io import RosParamReader
from migration_manager.instance import Hooks, ManagedInstance, Retiring, prepare_process


class ActivationLog(Progress):
    """Times the way from an activation to the first velocity command (logged with that command)."""

    def __init__(self, node: MoveBaseNode) -> None:
        self.node = node
        self.activated_at: Optional[float] = None   # monotonic time of the last activation, until its first command
        self.steps: Dict[str, float] = {}           # monotonic times of the steps after the last activation
        self.commanding = threading.Event()      # the first velocity command since the last activation went out

    def activated(self) -> None:
        self.commanding.clear()
        self.activated_at = time.monotonic()
        self.steps = {}

    def step(self, name: str) -> None:
        if self.activated_at is not None:
            self.steps[name] = time.monotonic()

    def commanded(self) -> None:
        if self.activated_at is None:
            return
        self.commanding.set()
        since = time.monotonic() - self.activated_at
        steps = ', '.join(f'{name} {1000 * (t - self.activated_at):.0f}' for name, t in self.steps.items()
                          if t >= self.activated_at)
        self.activated_at = None
        times = self.node.control_times
        cycle = times[-1] if times else math.nan
        rospy.loginfo(f'move_base: first velocity command {1000 * since:.0f} ms after becoming active'
                      f'{f" (then, in ms: {steps})" if steps else ""}; '
                      f'its control cycle took {1000 * cycle:.0f} ms')


class MoveBaseMigration(Hooks):
    """The managed instance's hooks for a :class:`MoveBaseNode` built as a standby (``standby=True``): creates
    the instance (once the node is complete) and starts the node with it as its output gate."""

    def __init__(self, node: MoveBaseNode) -> None:
        self.node = node
        self.handover: Optional[HandOver] = None             # set_state's goals, taken over when outputs open
        self.retiring = Retiring()               # a frozen instance's services, unregistered after the freeze
        self.openings = 0                        # outputs opened so far (the services belong to the last)
        self.log = ActivationLog(node)
        node.progress = self.log
        # the managed instance last: a standby is announced (and may be promoted) once the node is complete
        self.instance = ManagedInstance('move_base', self)
        node.start(self.instance)

    def standby_ready(self) -> bool:
        """Promotable without a stall: the node is complete and its local costmap follows the sensors (each
        source with an expected rate sent a scan within it). A clone promoted before its first scans waits for
        them in its first control cycle: cold cloud -> robot hand-overs took 2.6-6.6 s (median) with the clone
        just started on the capped robot. And its action server hears every client: a goal sent right after
        the promotion must not be lost to a subscription still connecting."""
        node = self.node
        return (node.ready.is_set() and not node.dormant and node.local_costmap.sensors_current(warn=False)
                and node.server.clients_connected())

    # ------------------------------------------------------------------ state
    def get_state(self) -> Dict[str, Any]:
        return self._hand_over().to_dict()

    def _hand_over(self) -> HandOver:
        node = self.node
        a = node.server.action_server
        with a.lock, node.server.lock:
            if self.handover is not None:                  # promoted, not opened yet: what it was given
                return self.handover
            current, pending = node.server.goal_snapshot()
            pursuit = node.pursuit
            goal = next_goal = None
            if current is not None:
                gid = current.get_goal_id()
                if pursuit is not None and pursuit[0] == gid.id:
                    _, target, index, trigger = pursuit
                    plan = node.core.controlled_plan()
                    goal = GoalRecord(gid.id, gid.stamp.secs, gid.stamp.nsecs, node.global_frame, target.x,
                                      target.y, target.yaw, self._cancel_requested(current), index, trigger,
                                      () if plan is None else tuple(map(tuple, plan.tolist())))
                else:                                      # accepted, not started (or just finished) here
                    goal = self._record(current, *node.takeover_recovery.get(gid.id, (0, 'PLANNING_R', ())))
            if pending is not None:
                next_goal = self._record(pending, 0, 'PLANNING_R')
            seen_goals, seen_cancels = node.server.seen()
            return HandOver(goal, next_goal, tuple(seen_goals), tuple(seen_cancels))

    def _record(self, handle, recovery_index: int, recovery_trigger: str, plan=()) -> GoalRecord:
        """A goal as the client sent it (its own frame)."""
        gid, target = handle.get_goal_id(), handle.get_goal().target_pose
        p, q = target.pose.position, target.pose.orientation
        return GoalRecord(gid.id, gid.stamp.secs, gid.stamp.nsecs, target.header.frame_id.lstrip('/') or
                          self.node.global_frame, p.x, p.y, target_yaw((q.x, q.y, q.z, q.w)),
                          self._cancel_requested(handle), recovery_index, recovery_trigger, tuple(plan))

    @staticmethod
    def _cancel_requested(handle) -> bool:
        return handle.get_goal_status().status in (GoalStatus.PREEMPTING, GoalStatus.RECALLING)

    def set_state(self, state: Dict[str, Any]) -> None:
        node = self.node
        handover = parse_state(state, len(node.core.recoveries))
        a = node.server.action_server
        with a.lock, node.server.lock:
            if node.outputs_open:
                raise ValueError('move_base state: this instance is active; a state is taken over only on '
                                 'promotion')
            self.handover = handover
        if not handover.empty:
            rospy.loginfo(f'move_base: handed over: goal {handover.goal.id if handover.goal else None}, '
                          f'next goal {handover.next_goal.id if handover.next_goal else None}')

    @staticmethod
    def _action_goal(record: GoalRecord) -> MoveBaseActionGoal:
        msg = MoveBaseActionGoal()
        msg.goal_id.id = record.id
        msg.goal_id.stamp = rospy.Time(record.stamp_secs, record.stamp_nsecs)
        msg.header.stamp = msg.goal_id.stamp
        target = msg.goal.target_pose
        target.header.frame_id = record.frame
        target.header.stamp = msg.goal_id.stamp
        target.pose.position.x, target.pose.position.y = record.x, record.y
        target.pose.orientation.x, target.pose.orientation.y, target.pose.orientation.z, \
            target.pose.orientation.w = yaw_to_quaternion(record.yaw)
        return msg

    # ------------------------------------------------------------------ activation and freeze
    def on_active(self) -> None:
        self.log.activated()                     # the first velocity command after it is logged
        if not self.node.outputs_open:
            threading.Thread(target=self._open_outputs, name='open_outputs', daemon=True).start()

    def _open_outputs(self) -> None:
        """Action server (taking over the handed-over goals first), then services and reconfigure services: a
        goal handed over is controlled first (the registrations with the master wait for its first velocity
        command, at most two control periods: on the capped robot they competed with the first control cycle,
        whose command came 31-497 ms after the activation, median 171 ms)."""
        node = self.node
        self.log.step('opening')
        node.ready.wait()
        with node.open_lock:
            if node.outputs_open or self.instance.frozen or rospy.core.is_shutdown_requested():
                return
            self.retiring.close()              # promoted again before after_frozen ran: the same names
            with node.output_lock:
                node.outputs_open = True
            self.openings += 1
            opening = self.openings
            a = node.server.action_server
            with a.lock, node.server.lock:
                handover, self.handover = self.handover or HandOver(), None
                goals: List[Tuple[MoveBaseActionGoal, str, bool]] = []
                if handover.goal is not None:
                    g = handover.goal
                    node.takeover_recovery[g.id] = (g.recovery_index, g.recovery_trigger, g.plan)
                    goals.append((self._action_goal(g), 'active', g.cancel_requested))
                if handover.next_goal is not None:
                    goals.append((self._action_goal(handover.next_goal), 'pending',
                                  handover.next_goal.cancel_requested))
                replayed = node.server.start_with(goals, handover.seen_goals, handover.seen_cancels)
                self.log.step('server started')
            if replayed:
                rospy.loginfo(f'move_base: sent while no instance was active, taken up: {", ".join(replayed)}')
        if goals:
            self.log.commanding.wait(2.0 / node.core.cfg.controller_frequency)
        with node.open_lock:
            if not node.outputs_open or self.openings != opening:    # frozen meanwhile (and opened again)
                return
            node.open_services()
        rospy.loginfo(f'move_base: active{f" with goal {handover.goal.id}" if handover.goal else ""}')

    def on_frozen(self) -> None:
        """Outputs closed for good: no velocity command from now on (not even a zero one: the next instance
        commands), no status for the goal (it continues in the next instance), no services."""
        node = self.node
        with node.output_lock:
            node.outputs_open = False
        with node.open_lock:
            node.server.release()
            node.pursuit = None
            self.handover = None
            self.retiring.add(*node.take_services())       # unregistered once the freeze was answered

    def after_frozen(self) -> None:
        """The goal dropped (the control loop ends at its next look: the instance is frozen; dropping it here does
        not make the freeze wait for a control cycle), the services unregistered."""
        with self.node.open_lock:
            if self.instance.frozen:           # not promoted again meanwhile (a rolled-back migration)
                self.node.core.reset()
            self.retiring.close()

    # ------------------------------------------------------------------ dormancy
    def on_sleep(self) -> None:
        """Dormant (a frozen instance the manager keeps for the next migration here): the sensor, odometry and
        tf subscriptions closed, the costmaps paused with their obstacles forgotten. The process, its
        parameters, registrations and prepared action server stay, so waking takes a subscription, not a
        start-up (a clone starting under the robot's CPU cap took 17-27 s)."""
        with self.node.open_lock:
            self.node.dormant = True
            self.node.pause_inputs()

    def on_wake(self) -> None:
        """A standby again: sensors, odometry and tf subscribed anew, costmaps updating; ready once the local
        costmap is current (``standby_ready``)."""
        with self.node.open_lock:
            self.node.resume_inputs()
            self.node.dormant = False


@cnr_params.exit_on_config_error
def main() -> None:
    """The ``move_base`` executable: a node on its own, or (``~migration/role`` set) a managed standby."""
    init_node('move_base')
    try:
        reader = RosParamReader()
        params = read_navigation_params(reader, rospy.get_name())
        for warning in params.warnings:
            rospy.logwarn(warning)
        # ManagedInstance's rule, known before the first subscriber: a managed instance's subscriptions carry
        # its host in their caller id
        managed = prepare_process()
        node = MoveBaseNode(params, standby=managed)
        if managed:
            MoveBaseMigration(node)
        else:
            node.start()
    except Exception:                 # stopped (Ctrl-C) while starting: rospy calls fail, that is no error
        if rospy.is_shutdown():
            return
        raise
    calls = dict(reader.calls)
    rospy.loginfo(f'move_base ready: {sum(calls.values())} parameter calls before the reconfigure servers '
                  f'({", ".join(f"{k} {v}" for k, v in sorted(calls.items()))}); controller '
                  f'{node.core.cfg.controller_frequency:g} Hz, planner {node.core.cfg.planner_frequency:g} Hz')
    rospy.spin()
