"""move_base-compatible navigation node (ROS I/O around :mod:`cnr_navigation.core`).

Interface as move_base (navigation@noetic-devel ``move_base.cpp``); see the package README for
the full list of topics, services and parameters.

The node runs on its own (:meth:`MoveBaseNode.start` without a gate: always active). What makes it movable by
migration_manager (standby, promotion with the client's goal, freeze, dormancy) is the adapter in
:mod:`cnr_navigation.move_base_migration`, which wraps the node and gives it its managed instance as the
:class:`OutputGate`.
"""
from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from typing import Callable, Deque, Dict, List, Optional, Protocol, Tuple

import numpy as np
import rospy
import tf2_ros
from dynamic_reconfigure.server import Server as ReconfigureServer
from dynamic_reconfigure.srv import Reconfigure as ReconfigureSrv
from geometry_msgs.msg import PoseStamped, Twist
from move_base_msgs.msg import MoveBaseAction, MoveBaseActionGoal, MoveBaseFeedback, MoveBaseGoal, RecoveryStatus
from nav_msgs.msg import Odometry, Path
from nav_msgs.srv import GetPlan, GetPlanResponse
from std_srvs.srv import Empty, EmptyResponse

from cnr_runtime import quiet_at_shutdown
from cnr_navigation.action_server import TakeoverActionServer
from cnr_navigation.cfg import DWAPlannerConfig, MoveBaseConfig
from cnr_navigation.core.dwa import DWAController
from cnr_navigation.core.geometry import IDENTITY, Pose2D
from cnr_navigation.core.move_base import MoveBaseCore, Velocity, goal_problem
from cnr_navigation.core.param_reader import NavigationParams, dwa_config, move_base_config
from cnr_navigation.core.param_tables import GLOBAL_PLANNERS, LOCAL_PLANNERS
from cnr_navigation.core.planner import GlobalPlanner, PlanningError, path_with_headings
from cnr_navigation.core.recovery import ClearCostmapRecovery, Recovery, RotateRecovery
from cnr_navigation.costmap_ros import CostmapROS
from cnr_navigation.ros_io import TfHelper, path_msg, pose_stamped, pose_to_2d


class OutputGate(Protocol):
    """Whether the node may produce output: a managed instance (``migration_manager.instance.ManagedInstance``)
    or :class:`Unmanaged`."""

    managed: bool
    lock: threading.RLock           # held while a goal's status is decided (a freeze takes the state under it)

    @property
    def active(self) -> bool: ...   # outputs allowed now (the lease is held)

    @property
    def frozen(self) -> bool: ...   # outputs closed for good: the goal belongs to the next instance

    def publisher(self, name: str, data_class, **kwargs) -> rospy.Publisher: ...


class Unmanaged:
    """The gate of a node that runs on its own: always active, never frozen, plain publishers."""

    managed = False
    active = True
    frozen = False

    def __init__(self) -> None:
        self.lock = threading.RLock()

    @staticmethod
    def publisher(name: str, data_class, **kwargs) -> rospy.Publisher:
        return rospy.Publisher(name, data_class, **kwargs)


class Progress:
    """What the node tells of a goal's way to its first velocity command (nothing, on its own; the migration
    adapter times the first command after an activation)."""

    def step(self, name: str) -> None:
        """A step of the way (the goal executing, started, the outputs opening)."""

    def commanded(self) -> None:
        """A velocity command went out (called under the node's output lock)."""


class _RecoveryBackend:
    """What the recovery behaviours see of the node."""

    def __init__(self, node: 'MoveBaseNode') -> None:
        self.node = node

    def robot_pose(self) -> Optional[Pose2D]:
        return self.node.local_costmap.robot_pose()

    def clear_costmaps(self, affected_maps: str, reset_distance: float, layer_names: List[str],
                       invert_area_to_clear: bool) -> None:
        maps = {'global': [self.node.global_costmap], 'local': [self.node.local_costmap],
                'both': [self.node.global_costmap, self.node.local_costmap]}[affected_maps]
        for cm in maps:
            robot = cm.robot_pose()
            if robot is not None:
                cm.clear(robot, reset_distance, invert_area_to_clear, layer_names)

    def in_collision(self, pose: Pose2D) -> bool:
        return self.node.local_costmap.in_collision(pose)


class MoveBaseNode:
    """The node: builds costmaps, planner, controller and the state machine, and serves the action.

    Args:
        params: the node's parameters.
        standby: start as a standby (the migration adapter's): the action server prepared but not started and
            the reconfigure services closed until :meth:`open_services`.
    """

    def __init__(self, params: NavigationParams, standby: bool = False) -> None:
        self.params = params
        self.global_frame = params.global_frame
        self.standby = standby
        self.gate: Optional[OutputGate] = None   # set by start(), once the node is complete
        self.progress = Progress()
        self.output_lock = threading.RLock()     # outputs_open vs. each publication
        self.outputs_open = False                # action server, services and topics open (active, not frozen)
        self.open_lock = threading.Lock()        # opening vs. closing the outputs
        self.takeover_recovery: Dict[str, Tuple[int, str, tuple]] = {}   # goal id -> recovery state, plan
        # (goal id, target in the global frame, next recovery index, trigger) of the goal the state machine
        # pursues; replaced whole, so get_state reads it without the state machine's lock
        self.pursuit: Optional[Tuple[str, Pose2D, int, str]] = None
        self.services: List[rospy.Service] = []
        self.reconfigure_servers: List[ReconfigureServer] = []
        self.ready = threading.Event()           # the node is complete (the instance may be promoted before)
        self.dormant = False                     # retired and asleep: no sensor subscriptions, costmaps paused
        self.announcement: Optional[Callable[[], None]] = None   # a taken-over goal's: after its first cycle
        self.server = TakeoverActionServer('move_base', MoveBaseAction, self._execute)
        self.tf_buffer = tf2_ros.Buffer()
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.tf = TfHelper(self.tf_buffer)
        self.velocity: Velocity = (0.0, 0.0)
        self.controller_lock = threading.RLock()
        self.control_times: Deque[float] = deque(maxlen=500)
        self.plan_times: Deque[float] = deque(maxlen=100)

        self.simple_goal_sub = rospy.Subscriber('move_base_simple/goal', PoseStamped, self._on_simple_goal,
                                                queue_size=1)
        self.odom_sub = rospy.Subscriber(params.odom_topic, Odometry, self._on_odom, queue_size=1)

        # global costmap and planner (navfn's namespace)
        self.global_costmap = CostmapROS(params.global_costmap, self.tf, self._costmaps_active, self._may_output)
        self._reconfigure(*self.global_costmap.servers)
        self.planner = GlobalPlanner(params.planner)

        # local costmap and controller (DWAPlannerROS's namespace)
        self.local_costmap = CostmapROS(params.local_costmap, self.tf, self._costmaps_active, self._may_output)
        self._reconfigure(*self.local_costmap.servers)
        self.dwa = DWAController(params.dwa, params.move_base.controller_frequency)
        self.dwa_extra = dict(params.dwa_extra)
        self._dwa_defaults: Optional[Dict] = None
        self.dwa_server = ReconfigureServer(DWAPlannerConfig, self._on_dwa_cfg, '~DWAPlannerROS')
        self._reconfigure(self.dwa_server)

        rb = _RecoveryBackend(self)
        recoveries: List[Recovery] = []
        for r in params.recoveries:
            if r.clear is not None:
                recoveries.append(ClearCostmapRecovery(r.name, r.clear, rb))
            elif r.rotate is not None:
                recoveries.append(RotateRecovery(r.name, r.rotate, rb))
        self.core = MoveBaseCore(params.move_base, self, recoveries, sync_planner=False)

        self._planner_thread = threading.Thread(target=self._planner_loop, name='planner', daemon=True)
        self._planner_thread.start()
        self._mb_defaults: Optional[Dict] = None
        self.mb_server = ReconfigureServer(MoveBaseConfig, self._on_move_base_cfg)
        self._reconfigure(self.mb_server)

    def start(self, gate: Optional[OutputGate] = None) -> None:
        """Open the output publishers through ``gate`` (None: :class:`Unmanaged`); a node on its own (not a
        standby) opens its action server and services at once."""
        self.gate = gate if gate is not None else Unmanaged()
        pub = self.gate.publisher
        self.cmd_pub = pub('cmd_vel', Twist, queue_size=1)
        self.current_goal_pub = pub('~current_goal', PoseStamped, queue_size=1)
        self.action_goal_pub = pub('move_base/goal', MoveBaseActionGoal, queue_size=1)
        self.recovery_status_pub = pub('move_base/recovery_status', RecoveryStatus, queue_size=1)
        self.plan_pub = pub('~NavfnROS/plan', Path, queue_size=1)
        self.dwa_global_plan_pub = pub('~DWAPlannerROS/global_plan', Path, queue_size=1)
        self.local_plan_pub = pub('~DWAPlannerROS/local_plan', Path, queue_size=1)
        for cm in (self.global_costmap, self.local_costmap):
            cm.open_publishers(pub)
        if self.standby:
            self.server.prepare()          # a standby's action server waits, connected, for its promotion
        self.ready.set()
        if not self.standby:
            self.open_outputs()

    # ================================================================================================
    # NavigationBackend for the state machine

    def robot_pose(self) -> Optional[Pose2D]:
        return self.global_costmap.robot_pose()

    def check_goal(self, goal: Pose2D) -> None:
        if self.global_costmap.has_map:
            self.planner.check_goal(self.global_costmap.planning_grid(static_only=True), goal)

    def make_plan(self, start: Pose2D, goal: Pose2D) -> np.ndarray:
        if not self.global_costmap.has_map:
            raise PlanningError('no_map', 'The global costmap has no map yet.')
        t0 = time.perf_counter()
        plan = self.planner.make_plan(self.global_costmap.planning_grid(), start, goal)
        self.plan_times.append(time.perf_counter() - t0)
        self._out(self.plan_pub, path_msg(plan, self.global_frame, rospy.Time.now()))
        return plan

    def set_plan(self, plan: np.ndarray) -> bool:
        with self.controller_lock:
            ok = self.dwa.set_plan(plan)
        self._out(self.dwa_global_plan_pub, path_msg(plan, self.global_frame, rospy.Time.now()))
        return ok

    def _global_to_local(self) -> Optional[Pose2D]:
        local_frame = self.local_costmap.costmap.cfg.global_frame
        if local_frame == self.global_frame:
            return IDENTITY
        found = self.tf.lookup(local_frame, self.global_frame)
        return found[0] if found else None

    def compute_velocity(self) -> Optional[Velocity]:
        pose = self.local_costmap.robot_pose()
        g2l = self._global_to_local()
        if pose is None or g2l is None:
            return None
        with self.controller_lock, self.local_costmap.lock:
            result = self.dwa.compute_velocity(pose, self.velocity, self.local_costmap.costmap, g2l)
        stamp = rospy.Time.now()
        self._out(self.local_plan_pub, path_msg(result.trajectory, self.local_costmap.costmap.cfg.global_frame, stamp))
        if result.cmd is None:
            rospy.logwarn_throttle(2.0, 'DWA planner failed to produce path.')
        return result.cmd

    def is_goal_reached(self) -> bool:
        pose = self.local_costmap.robot_pose()
        g2l = self._global_to_local()
        if pose is None or g2l is None:
            return False
        with self.controller_lock:
            return self.dwa.is_goal_reached(pose, self.velocity, g2l)

    def sensors_current(self) -> bool:
        return self.local_costmap.sensors_current()

    # ================================================================================================
    # outputs

    def _may_output(self) -> bool:
        """Publish now? Only while the outputs are open and the gate is active (the lease held, if managed)."""
        return self.outputs_open and self.gate is not None and self.gate.active

    def _out(self, publisher: rospy.Publisher, msg) -> None:
        with self.output_lock:              # on_frozen closes under this lock: nothing goes out after it
            if self._may_output():
                publisher.publish(msg)
                if publisher is self.cmd_pub:
                    self.progress.commanded()

    def _conclude(self, terminal, **kwargs) -> bool:
        """Give the current goal a terminal status (``terminal`` is a SimpleActionServer setter), unless this
        instance is frozen: its state, with the goal in it, was taken under the instance lock and the goal is
        the next instance's to conclude. A lapsed lease does not hold the status back."""
        with self.gate.lock:
            if self.gate.frozen or not self.server.started:
                return False
            terminal(**kwargs)
            return True

    def _reconfigure(self, *servers: ReconfigureServer) -> None:
        """Keep the dynamic_reconfigure servers; a standby closes their services until it is active."""
        for server in servers:
            self.reconfigure_servers.append(server)
            if self.standby:
                server.set_service.shutdown('standby')
                server.set_service = None

    def open_outputs(self) -> None:
        """A node on its own: the action server and the services open at once."""
        with self.open_lock:
            with self.output_lock:
                self.outputs_open = True
            self.server.start_with()
            self.open_services()

    def open_services(self) -> None:
        """Register ``~make_plan``, ``~NavfnROS/make_plan``, ``~clear_costmaps`` and the reconfigure services
        a standby closed (under ``open_lock``)."""
        self.services = [rospy.Service('~make_plan', GetPlan, self._make_plan_service),
                         rospy.Service('~NavfnROS/make_plan', GetPlan, self._navfn_make_plan),
                         rospy.Service('~clear_costmaps', Empty, self._clear_costmaps_service)]
        for server in self.reconfigure_servers:
            if server.set_service is None:
                server.set_service = rospy.Service(server.ns + 'set_parameters', ReconfigureSrv,
                                                   server._set_callback)

    def take_services(self) -> list:
        """The services :meth:`open_services` registered, taken from the node (to be unregistered; under
        ``open_lock``)."""
        taken: list = list(self.services)
        self.services = []
        for server in self.reconfigure_servers:
            taken.append(server.set_service)
            server.set_service = None
        return taken

    def _note_pursuit(self, goal_id: Optional[str]) -> None:
        """Record the goal the state machine pursues (None: none) with its recovery state."""
        goal = self.core.goal
        if goal_id is None or goal is None:
            self.pursuit = None
            return
        self.pursuit = (goal_id, goal, *self.core.recovery_state())

    def pause_inputs(self) -> None:
        """Odometry and tf unsubscribed, the costmaps asleep (their sensors unsubscribed, obstacles forgotten)."""
        self.odom_sub.unregister()
        self.tf_listener.unregister()
        for cm in (self.global_costmap, self.local_costmap):
            cm.sleep()
        self.velocity = (0.0, 0.0)

    def resume_inputs(self) -> None:
        """Odometry and tf subscribed anew (tf from an empty buffer: the old one is stale), costmaps updating."""
        self.tf_buffer.clear()
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.odom_sub = rospy.Subscriber(self.params.odom_topic, Odometry, self._on_odom, queue_size=1)
        for cm in (self.global_costmap, self.local_costmap):
            cm.wake()

    # ================================================================================================
    # callbacks

    def _costmaps_active(self) -> bool:
        return not self.dormant and (not self.core_cfg_shutdown_costmaps() or self.server.is_active())

    def core_cfg_shutdown_costmaps(self) -> bool:
        core = getattr(self, 'core', None)
        return bool(core is not None and core.cfg.shutdown_costmaps)

    def _on_odom(self, msg: Odometry) -> None:
        self.velocity = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)

    @quiet_at_shutdown
    def _on_simple_goal(self, msg: PoseStamped) -> None:
        rospy.logdebug('In ROS goal callback, wrapping the PoseStamped in the action message and re-sending to '
                       'the server.')
        goal = MoveBaseActionGoal()
        goal.header.stamp = rospy.Time.now()
        goal.goal.target_pose = msg
        self._out(self.action_goal_pub, goal)

    def publish_zero(self) -> None:
        self._out(self.cmd_pub, Twist())

    def _publish_cmd(self, cmd: Velocity) -> None:
        msg = Twist()
        msg.linear.x, msg.angular.z = cmd
        self._out(self.cmd_pub, msg)

    def _to_global(self, target: PoseStamped) -> Optional[PoseStamped]:
        """``goalToGlobalFrame``: the pose in the global frame (latest transform), None if tf has none."""
        frame = target.header.frame_id.lstrip('/')
        if not frame or frame == self.global_frame:
            return target
        found = self.tf.lookup(self.global_frame, frame)
        if found is None:
            rospy.logwarn(f'Failed to transform the goal pose from {frame} into the {self.global_frame} frame')
            return None
        pose = found[0].compose(pose_to_2d(target.pose))
        return pose_stamped(pose, self.global_frame, target.header.stamp)

    def _start_goal(self, target: PoseStamped) -> bool:
        """Validate and start a goal; abort it (and return False) if it is unusable."""
        self._announce()                       # (a goal preempted before its first cycle)
        goal_id = self.server.current_goal.get_goal_id().id
        takeover = self.takeover_recovery.pop(goal_id, None)
        p, q = target.pose.position, target.pose.orientation
        problem = goal_problem(p.x, p.y, p.z, (q.x, q.y, q.z, q.w))
        if problem is not None:
            rospy.logwarn(f'{problem[0]}: {problem[1]}')
            self.core.reset()
            self._conclude(self.server.set_aborted, text=problem[0])
            return False
        goal = self._to_global(target)
        if goal is None:
            self.core.reset()
            self._conclude(self.server.set_aborted, text=f'Failed to transform the goal pose from '
                                                         f'{target.header.frame_id} into the {self.global_frame} frame')
            return False
        p, q = goal.pose.position, goal.pose.orientation
        outcome = self.core.new_goal(p.x, p.y, (q.x, q.y, q.z, q.w), rospy.get_time(), z=p.z,
                                     checked=takeover is not None)
        if outcome is None and takeover is not None:
            self.core.restore_recovery(takeover[0], takeover[1])
            if takeover[2]:                    # it was being controlled: along its plan, without planning first
                self.core.restore_plan(np.array(takeover[2]), rospy.get_time())
        self._note_pursuit(goal_id if outcome is None else None)
        self.progress.step('goal started')
        if outcome is not None:
            self._conclude(self.server.set_aborted, text=outcome.text)
            return False
        with self.controller_lock:
            self.dwa.reset()
        goal.header.frame_id = self.global_frame
        if takeover is None:
            self._out(self.current_goal_pub, goal)
            rospy.loginfo(f'move_base: new goal ({p.x:.2f}, {p.y:.2f}) in {self.global_frame}')
        else:   # the goal continues: its first velocity command before anything else goes out (the capped robot)
            def announce() -> None:
                self._out(self.current_goal_pub, goal)
                rospy.loginfo(f'move_base: continuing goal {goal_id} ({p.x:.2f}, {p.y:.2f}) in {self.global_frame}, '
                              f'taken over from the previous instance (next recovery {takeover[0]}, {takeover[1]}'
                              f'{f", along its plan of {len(takeover[2])} poses" if takeover[2] else ""})')
            self.announcement = announce
        return True

    def _handed_over(self) -> bool:
        """Frozen (or superseded): the goal belongs to the next instance."""
        return self.gate is not None and (self.gate.frozen or not self.outputs_open)

    def _leave_goal(self) -> None:
        """End the execute callback of a frozen instance without a terminal status: wait until on_frozen has
        released the server's goal (else actionlib would abort a goal left active)."""
        while self.server.is_active() and not rospy.core.is_shutdown_requested():
            time.sleep(0.01)

    def _announce(self) -> None:
        """What a taken-over goal's start held back until its first control cycle (see ``_start_goal``)."""
        announce, self.announcement = self.announcement, None
        if announce is not None:
            announce()

    @quiet_at_shutdown
    def _execute(self, goal: MoveBaseGoal) -> None:
        """The action's execute callback: ``MoveBase::executeCb``."""
        self.progress.step('executing')
        try:
            self._run_goal(goal)
        finally:
            self._announce()                   # (the goal ended before its first cycle)
            if self._handed_over():    # actionlib aborts a goal left active: return once it is released
                self._leave_goal()

    def _run_goal(self, goal: MoveBaseGoal) -> None:
        if not self._start_goal(goal.target_pose):
            return
        frequency = self.core.cfg.controller_frequency
        rate = rospy.Rate(frequency)
        paused = False
        while not rospy.is_shutdown():
            if self._handed_over():
                return
            if self.core.cfg.controller_frequency != frequency:
                frequency = self.core.cfg.controller_frequency
                rate = rospy.Rate(frequency)
            if self.server.is_preempt_requested():
                if self.server.is_new_goal_available():
                    with self.gate.lock:               # accepting publishes: not once the state was taken
                        new_goal = None if self.gate.frozen else self.server.accept_new_goal()
                    if new_goal is None:
                        continue
                    if not self._start_goal(new_goal.target_pose):
                        self.publish_zero()
                        return
                else:
                    self.core.reset()
                    self.publish_zero()
                    if self._conclude(self.server.set_preempted):
                        return
                    continue
            if not self.gate.active:                   # the lease lapsed: no output until it is renewed
                if not paused:
                    paused = True
                    rospy.logwarn('move_base: lease lapsed, control paused (no velocity commands)')
                self._sleep(rate)
                continue
            if paused:
                paused = False
                self.core.resume(rospy.get_time())
                rospy.loginfo('move_base: lease renewed, control resumed')
            start_wall = time.perf_counter()
            result = self.core.cycle(rospy.get_time())
            elapsed = time.perf_counter() - start_wall
            self.control_times.append(elapsed)
            if result.cmd is not None:                 # the command first, then what reports on it
                self._publish_cmd(result.cmd)
            self._announce()
            if result.pose is not None:
                feedback = MoveBaseFeedback(base_position=pose_stamped(result.pose, self.global_frame,
                                                                       rospy.Time.now()))
                with self.output_lock:
                    if self._may_output():
                        self.server.publish_feedback(feedback)
            if result.recovery is not None:
                self._publish_recovery_status(result)
            if result.outcome is None and self.pursuit is not None:
                self._note_pursuit(self.pursuit[0])
            if result.outcome is not None:
                self.publish_zero()
                conclude = self.server.set_succeeded if result.outcome.status == 'SUCCEEDED' else \
                    self.server.set_aborted
                if self._conclude(conclude, text=result.outcome.text):
                    return
                continue                               # frozen meanwhile: the next instance concludes it
            if elapsed > 1.0 / frequency:
                rospy.logwarn_throttle(5.0, f'Control loop missed its desired rate of {frequency:.4f}Hz... the loop '
                                            f'actually took {elapsed:.4f} seconds')
            if not self._sleep(rate):
                break
        if self.server.is_active():
            self.core.reset()
            if self.gate.managed:                      # the goal may continue in another instance
                self.server.release()
            else:
                self.server.set_aborted(text='Aborting on the goal because the node has been killed')

    @staticmethod
    def _sleep(rate: rospy.Rate) -> bool:
        """One control period; False when the node is shutting down."""
        try:
            rate.sleep()
        except rospy.exceptions.ROSTimeMovedBackwardsException:
            pass
        except rospy.ROSInterruptException:
            return False
        return True

    def _publish_recovery_status(self, result) -> None:
        index, total, name = result.recovery
        msg = RecoveryStatus()
        msg.pose_stamped = pose_stamped(result.pose, self.global_frame, rospy.Time.now())
        msg.current_recovery_number = index
        msg.total_number_of_recoveries = total
        msg.recovery_behavior_name = name
        self._out(self.recovery_status_pub, msg)

    def _planner_loop(self) -> None:
        """``MoveBase::planThread``: plan whenever the state machine wants a plan."""
        while not rospy.is_shutdown():
            try:
                now = rospy.get_time()
                if self.core.planner_due(now) and self.gate is not None and self.gate.active:
                    self.core.run_planner(now, clock=rospy.get_time)
                else:
                    time.sleep(0.2 if self.dormant else 0.02)
            except Exception as exc:     # never let the planner thread die silently
                if rospy.core.is_shutdown_requested():
                    return                # e.g. a plan published onto a topic the shutdown closed
                rospy.logerr_throttle(5.0, f'planner thread: {exc!r}')
                time.sleep(0.1)

    # ================================================================================================
    # services

    def _plan_between(self, start: Pose2D, goal: Pose2D, tolerance: float) -> np.ndarray:
        return self.planner.make_plan(self.global_costmap.planning_grid(), start, goal, tolerance)

    def _make_plan_service(self, req) -> GetPlanResponse:
        """``~make_plan``: as ``MoveBase::planService``."""
        if self.server.is_active():
            rospy.logerr('move_base must be in an inactive state to make a plan for an external user')
            raise rospy.ServiceException('move_base must be in an inactive state to make a plan for an external user')
        return self._plan_service(req, clear=self.core.cfg.make_plan_clear_costmap,
                                  add_goal=self.core.cfg.make_plan_add_unreachable_goal)

    def _navfn_make_plan(self, req) -> GetPlanResponse:
        """``~NavfnROS/make_plan``: the planner's own service."""
        return self._plan_service(req, clear=False, add_goal=False)

    def _plan_service(self, req, clear: bool, add_goal: bool) -> GetPlanResponse:
        empty = GetPlanResponse()
        empty.plan.header.frame_id = self.global_frame
        empty.plan.header.stamp = rospy.Time.now()
        gp, gq = req.goal.pose.position, req.goal.pose.orientation
        problem = goal_problem(gp.x, gp.y, gp.z, (gq.x, gq.y, gq.z, gq.w))
        if problem is not None:
            rospy.logwarn(f'make_plan: {problem[0]}: {problem[1]}')
            return empty
        if not self.global_costmap.has_map:
            rospy.logwarn('make_plan: the global costmap has no map yet')
            return empty
        if req.start.header.frame_id:
            start_msg = self._to_global(req.start)
            start = pose_to_2d(start_msg.pose) if start_msg is not None else None
        else:
            start = self.robot_pose()
        goal_msg = self._to_global(req.goal)
        if start is None or goal_msg is None:
            rospy.logerr('move_base cannot make a plan for you because it could not get the start pose of the robot')
            return empty
        goal = pose_to_2d(goal_msg.pose)
        if clear:
            robot = self.global_costmap.robot_pose()
            if robot is not None:
                self.global_costmap.clear(robot, 2.0 * self.params.clearing_radius, invert=True)
        try:
            plan = self._plan_between(start, goal, max(0.0, req.tolerance))
        except PlanningError as err:
            rospy.logwarn(f'make_plan: {err.text}')
            return empty
        if add_goal and (abs(plan[-1, 0] - goal.x) > 1e-9 or abs(plan[-1, 1] - goal.y) > 1e-9):
            plan = path_with_headings(np.append(plan[:, 0], goal.x), np.append(plan[:, 1], goal.y), goal.yaw)
        resp = GetPlanResponse()
        resp.plan = path_msg(plan, self.global_frame, rospy.Time.now())
        return resp

    def _clear_costmaps_service(self, req) -> EmptyResponse:
        self.global_costmap.clear()
        self.local_costmap.clear()
        rospy.loginfo('move_base: costmaps cleared')
        return EmptyResponse()

    # ================================================================================================
    # dynamic_reconfigure

    def _on_move_base_cfg(self, config: Dict, level: int) -> Dict:
        if self._mb_defaults is None:
            self._mb_defaults = dict(config)
        if config.get('restore_defaults'):
            config = dict(self._mb_defaults)
            config['restore_defaults'] = False
        for key, allowed in (('base_global_planner', GLOBAL_PLANNERS), ('base_local_planner', LOCAL_PLANNERS)):
            if config[key] not in allowed:
                rospy.logerr(f'{key}: {config[key]} is not available (implemented: {", ".join(allowed)}); '
                             'keeping the current one')
                config[key] = getattr(self.params, key)
        new = move_base_config(config)
        with self.core.lock:
            self.core.cfg = new
            for rec in self.core.recoveries:
                if isinstance(rec, ClearCostmapRecovery) and rec.name == 'conservative_reset':
                    rec.cfg = dataclasses.replace(rec.cfg, reset_distance=new.conservative_reset_dist)
        with self.controller_lock:
            self.dwa.set_controller_frequency(new.controller_frequency)
        return config

    def _on_dwa_cfg(self, config: Dict, level: int) -> Dict:
        if self._dwa_defaults is None:
            self._dwa_defaults = dict(config)
        if config.get('restore_defaults'):
            config = dict(self._dwa_defaults)
            config['restore_defaults'] = False
        with self.controller_lock:
            self.dwa.cfg = dwa_config(config, self.dwa_extra)
        return config

