"""The ``task_runner`` node: runs a plan of tasks (thesis §3.4.1: "drive to the end of the corridor and back")
one after the other, each under the link the plan sets, decided and evaluated by network_monitor's
migration_decider (see :mod:`cnr_mission.core.task` and the package README).

Per run: set the link (testbed emulator), put the robot at the task's start (the simulator's ``teleport``),
``~decide`` (the modules home, the network monitor's window filled with the new link for ``settle`` s, profile,
k-NN, placement; or the previous run's profile with ``reuse_profile``), drive the goals with
move_base's action, measure T_task (sim time) and B_task (the robot computer's battery, ``battery_topic``; the
base's, ``base_battery_topic``, recorded beside it as ``b_base``), both from the placement on (its cost is the
task's; the whole decision's, profile and placement, beside them: :mod:`cnr_mission.core.task`), ``~evaluate``,
append the row to the results file. A plan that was interrupted resumes after the last run with a row. Before a
session's first run the task is driven ``warmup_runs`` times, not recorded (the nodes still starting).

Exit status: 0 every run done, 2 bad configuration, 1 anything else.
"""
from __future__ import annotations

import collections
import math
import os
import time
from typing import Deque, Dict, List, Optional, Tuple

import actionlib
from actionlib.action_client import CommState
import rospy
from actionlib_msgs.msg import GoalStatus, GoalStatusArray
from geometry_msgs.msg import Pose2D
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from sensor_msgs.msg import BatteryState

import cnr_params
from cnr_mission.core.task import (GAVE_UP, SUCCEEDED, TOO_LONG, RunSpec, TaskSpec, append_result, battery_fields,
                                   charge_at, evaluable, load_plan, load_task, mission_status, read_results, resolve_force)
from cnr_msgs.msg import TaskDecision
from cnr_msgs.srv import Decide, EvaluateTask, Teleport
from cnr_navigation.goal_sequencer import wait_for_server
from cnr_params import ConfigError, Section
from cnr_params.ros import private_section
from cnr_runtime import init_node
from network_monitor.codes import A_BW_METHOD_WORD
from network_monitor.decider_codes import FORCE, MISSION_STATUS, PLACEMENT_WORD, REASON_WORD

FAILED_STATES = (GoalStatus.ABORTED, GoalStatus.REJECTED, GoalStatus.LOST, GoalStatus.RECALLED,
                 GoalStatus.PREEMPTED)
READINGS_KEPT = 3600        # a pack's readings kept (an hour at the simulator's 1 Hz): more than a task takes


class TaskRunner:
    def __init__(self) -> None:
        p = private_section('~')
        self.plan = load_plan(p.string('plan'))
        scenario = Section.from_file(p.string('scenario_file'))
        self.specs = {task: load_task(scenario, task) for task in self.plan.tasks}
        self.results = os.path.abspath(p.string('results'))
        testbed = p.string('testbed_config')
        self.testbed = None
        if testbed:
            from cnr_testbed.api import Testbed
            self.testbed = Testbed(testbed)
        self.server_timeout = p.number('server_timeout', positive=True)
        self.goal_ack_timeout = p.number('goal_ack_timeout', positive=True)
        self.last_sent = 0.0                        # wall time the current goal was (last) sent
        self.decide_timeout = p.number('decide_timeout', positive=True)
        self.warmup_runs = int(p.number('warmup_runs', nonnegative=True))
        decider = p.string('decider').rstrip('/')
        self.decide = rospy.ServiceProxy(f'{decider}/decide', Decide)
        self.evaluate = rospy.ServiceProxy(f'{decider}/evaluate', EvaluateTask)
        self.teleport = rospy.ServiceProxy(p.string('teleport_service'), Teleport)
        action = p.string('move_base_action').rstrip('/')
        self.client = actionlib.SimpleActionClient(action, MoveBaseAction)
        self.last_status = time.monotonic()         # wall time move_base's action status was last heard
        rospy.Subscriber(f'{action}/status', GoalStatusArray, self._on_status, queue_size=2)
        self.battery_wait = p.number('battery_wait', positive=True)
        # each pack's readings (sim time, percentage): the robot computer's (B_task) and the base's (b_base)
        self.battery: Deque[Tuple[float, float]] = collections.deque(maxlen=READINGS_KEPT)
        self.base_battery: Deque[Tuple[float, float]] = collections.deque(maxlen=READINGS_KEPT)
        self.link = None                            # the link the previous run set
        self.redecisions: List[TaskDecision] = []
        rospy.Subscriber(p.string('battery_topic'), BatteryState, self._on_battery, queue_size=2)
        rospy.Subscriber(p.string('base_battery_topic'), BatteryState, self._on_base_battery, queue_size=2)
        rospy.Subscriber(f'{decider}/decisions', TaskDecision, self._on_decision, queue_size=20)

    def _on_status(self, _msg: GoalStatusArray) -> None:
        self.last_status = time.monotonic()

    def _on_battery(self, msg: BatteryState) -> None:
        self.battery.append((rospy.Time.now().to_sec(), msg.percentage))

    def _on_base_battery(self, msg: BatteryState) -> None:
        self.base_battery.append((rospy.Time.now().to_sec(), msg.percentage))

    def _readings_after(self, t: float) -> None:
        """Wait (at most battery_wait s, wall) for a reading of each pack after sim time ``t``: a percentage at
        ``t`` is read between the readings around it."""
        deadline = time.monotonic() + self.battery_wait
        while not rospy.is_shutdown() and time.monotonic() < deadline and \
                not all(r and r[-1][0] > t for r in (self.battery, self.base_battery)):
            time.sleep(0.05)

    def _on_decision(self, msg: TaskDecision) -> None:
        if msg.event == TaskDecision.REDECIDED:
            self.redecisions.append(msg)
            self.say(f're-decided during the task: {PLACEMENT_WORD[msg.decision]} at RTT {1000 * msg.c_l:.0f} ms, R_bw '
                     f'{msg.r_bw:.3g} ({msg.message})')

    @staticmethod
    def say(text: str) -> None:
        print(f'[task {rospy.Time.now().to_sec():7.1f} s] {text}', flush=True)

    # ---------------------------------------------------------------- one run
    def _resend_unacknowledged(self, sent: float) -> None:
        """actionlib sends a goal once: one that no move_base status has acknowledged within goal_ack_timeout
        (lost to an instance whose subscription to this node was still connecting, e.g. a clone just promoted
        across a slow link) is sent again, same goal id and stamp (a server that has it ignores the copy)."""
        gh = self.client.gh
        if gh is None or gh.get_comm_state() != CommState.WAITING_FOR_GOAL_ACK:
            return
        if time.monotonic() - self.last_sent >= self.goal_ack_timeout:
            self.last_sent = time.monotonic()
            self.client.action_client.pub_goal.publish(gh.comm_state_machine.action_goal)
            self.say(f'goal {gh.comm_state_machine.action_goal.goal_id.id} not acknowledged after '
                     f'{time.monotonic() - sent:.1f} s: sent again')

    def to_start(self, spec: TaskSpec) -> None:
        """Put the robot at the task's start (the simulator's teleport)."""
        sx, sy, sa = spec.start
        self.teleport.wait_for_service(self.decide_timeout)
        res = self.teleport(Pose2D(sx, sy, sa), False)
        if not res.success:
            raise RuntimeError(f'could not put the robot at the start ({sx}, {sy}): {res.message}')

    def drive(self, spec: TaskSpec) -> List[str]:
        """Each of the task's goals in turn; the outcomes (stops at the first that did not succeed)."""
        outcomes: List[str] = []
        for x, y, yaw in spec.goals:
            goal = MoveBaseGoal()
            goal.target_pose.header.frame_id = 'map'
            goal.target_pose.header.stamp = rospy.Time.now()
            goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = x, y
            o = goal.target_pose.pose.orientation
            o.z, o.w = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
            self.client.send_goal(goal)
            t0 = rospy.Time.now().to_sec()
            sent = self.last_sent = time.monotonic()
            outcome = None
            while outcome is None and not rospy.is_shutdown():
                self._resend_unacknowledged(sent)
                state = self.client.get_state()
                if state == GoalStatus.SUCCEEDED:
                    # the status array says so before the result message comes: take the result too (bounded),
                    # else this goal's last transition reaches the client after the next goal replaced it and
                    # actionlib logs "a goal handle that we're not tracking"
                    self.client.wait_for_result(rospy.Duration(1.0))
                    outcome = SUCCEEDED
                elif state in FAILED_STATES:
                    outcome = GAVE_UP
                elif rospy.Time.now().to_sec() - t0 > spec.goal_timeout:
                    outcome = TOO_LONG
                elif time.monotonic() - self.last_status > self.server_timeout:
                    outcome = GAVE_UP       # the action server gone (e.g. move_base on a cut-off cloud, no failover)
                else:
                    time.sleep(0.05)
            if outcome != SUCCEEDED:
                self.client.cancel_all_goals()
            outcomes.append(outcome or GAVE_UP)
            self.say(f'goal ({x:.1f}, {y:.1f}): {outcomes[-1]} after {rospy.Time.now().to_sec() - t0:.1f} s')
            if outcome != SUCCEEDED:
                break
        return outcomes

    def run(self, i: int, n: int, r: RunSpec) -> Dict:
        force = resolve_force(r.force, self.decided.get(r.condition))
        task = self.plan.task_of(r)
        spec = self.specs[task]
        row: Dict = dict(id=r.id, condition=r.condition, task=task, force=force, wall_start=round(time.time(), 3))
        w0 = time.monotonic()
        if r.link is not None:
            row.update(rtt_ms=r.link.rtt_ms, rate_mbit=r.link.rate, loss=r.link.loss)
            if self.testbed is None:
                raise ConfigError('task_runner', 'testbed_config', f'run {r.id} sets a link but no testbed is given')
            self.testbed.set('both', delay=r.link.delay, rate=r.link.rate, loss=r.link.loss)
        link = '' if r.link is None else \
            f'RTT {r.link.rtt_ms:.0f} ms, {r.link.rate:g} Mbit/s, loss {100 * r.link.loss:.1f} %'
        self.say(f'run {i}/{n} {r.id} ({task}): {link or "link as it is"}'
                 + (f'; placement forced: {force}' if force else ''))
        # a new link: the monitor's window fills with it before the profile (the decider waits, after bringing
        # the modules home if it does; without a decision the runner waits)
        settle = self.plan.settle if r.link != self.link else 0.0
        if not r.decide:
            deadline = time.monotonic() + settle
            while time.monotonic() < deadline and not rospy.is_shutdown():
                time.sleep(0.1)
        self.link = r.link
        self.to_start(spec)
        self.redecisions = []
        # s: the placement and the whole decision (profile + placement; wall), and the sim time the decision ended
        placing = t_decision = decided_at = 0.0
        if r.decide:
            self.decide.wait_for_service(self.decide_timeout)
            d = self.decide(task=task, location=self.plan.location, force=FORCE[force], probe=True,
                            explore=r.explore, settle=settle, reuse_profile=r.reuse_profile)
            if not d.ok:
                raise RuntimeError(f'the decider refused: {d.message}')
            decided_at = rospy.Time.now().to_sec()
            self.say(f'decision: {d.message}')
            m = d.decision
            placing, t_decision = m.placing_time, m.profile_time + m.placing_time
            self.decided[r.condition] = PLACEMENT_WORD[m.decision]
            row.update(decision=PLACEMENT_WORD[m.decision], reason=REASON_WORD[m.reason],
                       policy=PLACEMENT_WORD[m.policy], confidence=m.confidence, votes_offload=m.votes_offload,
                       c_l=m.c_l, r_bw=m.r_bw, profile_method=A_BW_METHOD_WORD[m.profile_method], placed=m.placed,
                       placing_time=m.placing_time, placement=m.placement, t_decision=t_decision)
        if not wait_for_server(self.client, self.decide_timeout):
            raise RuntimeError('move_base\'s action server is not there')
        t0 = rospy.Time.now().to_sec()
        outcomes = self.drive(spec)
        t1 = rospy.Time.now().to_sec()
        t_task = t1 - t0 + placing
        self._readings_after(t1)
        comp, base = list(self.battery), list(self.base_battery)
        status = mission_status(outcomes, len(spec.goals))
        batteries = battery_fields((charge_at(comp, t0), charge_at(comp, t1)),
                                   (charge_at(base, t0), charge_at(base, t1)), decided=r.decide,
                                   at_placing=charge_at(comp, decided_at - placing),
                                   at_profile=charge_at(comp, decided_at - t_decision))
        b_task = batteries['b_task']
        row.update(mission_status=status, t_task=t_task, redecisions=len(self.redecisions), **batteries)
        if r.decide and not evaluable(b_task):
            # the decider's task is closed (it stops re-deciding) but nothing is labelled or learned from it
            self.evaluate(MISSION_STATUS[status], t_task, 0.0, False)
            self.say(f'{status}: T {t_task:.1f} s, no battery reading: the run is invalid (not evaluated, '
                     f'not learned)')
        elif r.decide:
            e = self.evaluate(MISSION_STATUS[status], t_task, b_task, r.learn)
            self.say(f'evaluation: {e.message}')
            if e.ok:
                # decision: what ran (a placement not made is evaluated as the one the task started with)
                row.update(value=e.result.value, good=e.result.good, label=PLACEMENT_WORD[e.result.label],
                           learned=e.result.learned, placement=e.result.placement,
                           decision=PLACEMENT_WORD[e.result.decision])
        else:
            self.say(f'{status}: T {t_task:.1f} s, B {b_task:.5f}')
        row['wall_time'] = round(time.monotonic() - w0, 2)
        return row

    def warm_up(self, task: str, k: int) -> None:
        """Drive ``task`` once as placed, not decided and not recorded: the session's nodes are still starting
        under the robot's CPU cap when it begins (config/task_runner.yaml ``warmup_runs``)."""
        spec = self.specs[task]
        self.to_start(spec)
        if not wait_for_server(self.client, self.decide_timeout):
            raise RuntimeError('move_base\'s action server is not there')
        t0 = rospy.Time.now().to_sec()
        outcomes = self.drive(spec)
        self.say(f'warm-up {k}/{self.warmup_runs} ({task}, not recorded): '
                 f'{mission_status(outcomes, len(spec.goals))} in {rospy.Time.now().to_sec() - t0:.1f} s')

    def spin(self) -> int:
        rows, warnings = read_results(self.results)
        for w in warnings:
            rospy.logwarn(w)
        done = {row['id'] for row in rows}
        self.decided: Dict[str, str] = {row['condition']: row['decision'] for row in rows if row['decision']}
        todo = [r for r in self.plan.runs if r.id not in done]
        n = len(self.plan.runs)
        self.say(f'{"+".join(self.plan.tasks)}@{self.plan.location}: {n} runs in the plan, {n - len(todo)} already done; '
                 f'results in {self.results}')
        try:
            for k in range(self.warmup_runs if todo else 0):
                self.warm_up(self.plan.task_of(todo[0]), k + 1)
        except (rospy.ServiceException, rospy.ROSException, RuntimeError) as exc:
            if not rospy.is_shutdown():
                self.say(f'warm-up failed: {exc}; the plan stops here (run it again to resume)')
            return 1
        for r in todo:
            if rospy.is_shutdown():
                return 1
            try:
                row = self.run(self.plan.runs.index(r) + 1, n, r)
            except (rospy.ServiceException, rospy.ROSException, RuntimeError) as exc:
                if rospy.is_shutdown():
                    return 1
                self.say(f'run {r.id} failed: {exc}; the plan stops here (run it again to resume)')
                return 1
            append_result(self.results, row)
        self.say(f'plan done: {n} runs in {self.results}')
        return 0


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('task_runner')
    raise SystemExit(TaskRunner().spin())
