"""The ``migration_decider`` node (robot): the network-aware decision of thesis §4.2.3-§4.2.6 (package README).

Before a task (``~decide``): a profile from the network monitor (``~profile_now``, optionally with an active
probe), the k-NN decision of :mod:`network_monitor.core.advisor`, and the task's modules placed through
migration_manager's ``~migrate``. During the task: every network profile is re-decided with hysteresis; a switch
migrates the modules (in a thread: the profile callback never blocks). After it (``~evaluate``): Eq. 4-5, the
label, the row appended to the ⟨task, location⟩'s training set. Each event is published on ``~decisions``.

Everything it calls is on the robot (the network monitor and the migration manager run there), each call
bounded by ``decider.service_timeout`` or the manager's own migration timeouts.
"""
from __future__ import annotations

import dataclasses
import math
import os
import threading
import time
from typing import Dict, Optional, Tuple

import rospy

import cnr_params
from cnr_msgs.msg import NetworkProfile, Placement, TaskDecision
from cnr_msgs.srv import (Decide, DecideResponse, EvaluateTask, EvaluateTaskResponse, Migrate, MigrateResponse,
                          ProfileNow)
from cnr_params import ConfigError, Section
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from migration_manager.codes import MODE, OUTCOME_WORD, TARGET
from network_monitor.codes import A_BW_METHOD, A_BW_METHOD_WORD
from network_monitor.decider_codes import EVENT, FORCE_WORD, MISSION_STATUS, MISSION_STATUS_WORD, PLACEMENT, REASON
from network_monitor.core.advisor import REDECISION, AdvisorError, Profile, RunningTask, TaskAdvisor
from network_monitor.core.decision import Decision
from network_monitor.core.decision_config import decision_config
from network_monitor.core.evaluation import OFFLOAD, ONLOAD


def profile_of(msg: NetworkProfile) -> Profile:
    return Profile(c_l=msg.rtt, r_bw=msg.r_bw, rtt_spread=msg.rtt_spread, loss=msg.loss,
                   method=A_BW_METHOD_WORD[msg.a_bw_method], alive=msg.alive, a_bw=msg.a_bw, c_bw=msg.c_bw)


class DeciderNode:
    def __init__(self) -> None:
        p = private_section('~')
        f = Section.from_file(p.string('config'))
        cfg = decision_config(f)
        overrides = {k: os.path.expanduser(p.string(k)) for k in ('training_dir', 'control_values') if p.string(k)}
        self.cfg = dataclasses.replace(cfg, **overrides)
        d = f.section('decider')
        self.service_timeout = d.number('service_timeout', positive=True)
        self.placement_timeout = d.number('placement_timeout', positive=True)
        self.profile_at_home = d.boolean('profile_at_home')
        self.link_wait = d.number('link_wait', positive=True)
        self.alive_since: Optional[float] = None      # monotonic time the periodic profiles began to say alive
        self.last_profile: Optional[Tuple[Profile, str]] = None     # the previous ~decide's profile and its note
        self.advisor = TaskAdvisor(self.cfg)
        self.lock = threading.Lock()
        self.active: Dict[str, str] = {}               # module -> host where active (from the manager)
        self.migrating = False
        self.pub = rospy.Publisher('~decisions', TaskDecision, queue_size=20, latch=True)
        self.profile_now = rospy.ServiceProxy(d.string('profile_service'), ProfileNow)
        self.migrate = rospy.ServiceProxy(d.string('migrate_service'), Migrate)
        rospy.Subscriber(d.string('placement_topic'), Placement, self._on_placement, queue_size=10)
        rospy.Subscriber(d.string('profile_topic'), NetworkProfile, self._on_profile, queue_size=10)
        rospy.Service('~decide', Decide, self._on_decide)
        rospy.Service('~evaluate', EvaluateTask, self._on_evaluate)
        r = self.cfg.redecision
        rospy.loginfo(f'migration_decider: k = {self.cfg.decision.k}, V_r = {self.cfg.v_r:g}, tasks '
                      f'{", ".join(t + " (" + "/".join(m) + ")" for t, m in self.cfg.tasks.items())}; training sets in '
                      f'{self.cfg.training_dir}; re-decision: margin {r.margin:g}, dwell {r.dwell:g} s'
                      + (f' (clearly better: {r.clear_margin:g}, {r.clear_dwell:g} s)' if r.clear_margin is not None
                         else '') + f', at most {r.max_migrations} migration(s) per {r.window:g} s')

    # ---------------------------------------------------------------- inputs
    def _on_placement(self, msg: Placement) -> None:
        with self.lock:
            self.active = {m: h for m, h, moving in zip(msg.modules, msg.hosts, msg.migrating) if h and not moving}

    def _on_profile(self, msg: NetworkProfile) -> None:
        now = time.monotonic()
        with self.lock:
            self.alive_since = (self.alive_since or now) if msg.alive else None
            if self.migrating:
                return
            switch = self.advisor.observe(profile_of(msg), now)
            if switch is None:
                return
            self.migrating = True
            running = self.advisor.running
        placement, d = switch
        hosts = self.advisor.hosts(running.task, placement)
        rospy.loginfo(f'migration_decider: re-decision during {running.task}@{running.location}: {placement} '
                      f'(RTT {1000 * msg.rtt:.0f} ms, R_bw {msg.r_bw:.3g}, votes {d.votes or "rule"}; wanted for '
                      f'{running.redecider.waited:.1f} s)')
        threading.Thread(target=self._redecide, args=(running, placement, d, msg, hosts, running.redecider.waited),
                         daemon=True).start()

    def _redecide(self, running: RunningTask, placement: str, d: Decision, msg: NetworkProfile,
                  hosts: Dict[str, str], waited: float) -> None:
        task, location = running.task, running.location
        try:
            t0 = time.monotonic()
            placed, moved, message, now = self.place(hosts)
            with self.lock:
                if self.advisor.running is running:      # (the task may have been evaluated meanwhile)
                    self.advisor.switched(now)
            out = self._message('redecided', task, location, placement, d, profile_of(msg), now)
            out.reason, out.placed, out.placing_time, out.migrations, out.message = \
                REASON[REDECISION], placed, time.monotonic() - t0, moved, f'wanted for {waited:.1f} s; {message}'

            self.pub.publish(out)
        finally:
            with self.lock:
                self.migrating = False

    # ---------------------------------------------------------------- placing
    def place(self, hosts: Dict[str, str]) -> Tuple[bool, int, str, Dict[str, str]]:
        """Order each module to its host (one at a time; the manager's ``~migrate`` returns when it is done or
        refused, and refuses a module that is already there). The manager is asked every time rather than
        trusting the last placement message, which may lag behind a migration that just finished. Returns (all
        placed, migrations done, a message, where each module is active now: a refused or rolled-back
        migration leaves it where it was, '' if it is active nowhere)."""
        moved, placed, notes = 0, 0, []
        now: Dict[str, str] = {}
        for module, host in hosts.items():
            now[module] = self._settled(module) or ''
            if not now[module]:
                notes.append(f'{module} -> {host}: not ordered (not active anywhere within '
                             f'{self.placement_timeout:g} s)')
                continue
            try:
                res = self.migrate(module, TARGET[host], MODE[''])
            except (rospy.ServiceException, rospy.ROSException) as exc:
                notes.append(f'{module} -> {host}: not ordered ({exc})')
                continue
            if res.ok and res.outcome == MigrateResponse.DONE:
                moved += 1
                placed += 1
                now[module] = host
                notes.append(f'{module} -> {host} in {res.duration:.1f} s ({res.message})')
            elif res.outcome == MigrateResponse.REFUSED and f'already on {host}' in res.message:
                placed += 1
                now[module] = host
                notes.append(f'{module} already on {host}')
            else:
                notes.append(f'{module} -> {host}: {OUTCOME_WORD[res.outcome]} ({res.message})')
        return placed == len(hosts), moved, '; '.join(notes), now

    def _settled(self, module: str) -> Optional[str]:
        """Where ``module`` is active once it is not starting or migrating (waits up to placement_timeout: the
        managed modules start a minute after launch on the capped robot); None if it never settles."""
        deadline = time.monotonic() + self.placement_timeout
        while not rospy.is_shutdown():
            with self.lock:
                here = self.active.get(module)
            if here is not None or time.monotonic() >= deadline:
                return here
            time.sleep(0.2)
        return None

    # ---------------------------------------------------------------- services
    def _message(self, event: str, task: str, location: str, placement: str, d: Decision, p: Profile,
                 hosts: Dict[str, str]) -> TaskDecision:
        out = TaskDecision(event=EVENT[event], task=task, location=location, decision=PLACEMENT[placement],
                           policy=PLACEMENT[d.policy], reason=REASON[d.reason], confidence=d.confidence,
                           votes_offload=d.votes.get(OFFLOAD, 0), votes_onload=d.votes.get(ONLOAD, 0), c_l=p.c_l,
                           r_bw=p.r_bw, rtt_spread=p.rtt_spread, loss=p.loss, profile_method=A_BW_METHOD[p.method],
                           placement=','.join(f'{m}={h}' for m, h in hosts.items()),
                           t_task=math.nan, b_task=math.nan, value=math.nan)
        out.header.stamp = rospy.Time.now()
        return out

    def _profile(self, req) -> Tuple[Profile, str, float]:
        """The profile a ~decide decides on, a note for its message and the profile's own time (s, wall: the
        network monitor's ``~profile_now``, its probe included; 0 when reused) (the package README, "Node
        migration_decider"): the previous one (``reuse_profile``), or a new one taken with the task's modules on
        the robot (``decider.profile_at_home``) no earlier than ``settle`` s after the request or, when modules
        were brought home, after they were (their traffic filled the link's queue until then), or after the
        network monitor began to hear the cloud (:meth:`_settle`)."""
        if req.reuse_profile and self.last_profile is not None:
            profile, note = self.last_profile
            return profile, note + 'the previous profile: ', 0.0
        t0 = time.monotonic()
        home_note, note = '', ''
        if self.profile_at_home and req.task in self.cfg.tasks:
            home = self.advisor.hosts(req.task, ONLOAD)
            with self.lock:
                away = [m for m, h in home.items() if self.active.get(m, h) != h]
            if away:        # their traffic (a cloud move_base is sent the laser scans) would load the link measured
                placed, moved, message, _ = self.place(home)
                home_note = f'brought home first ({message}; {time.monotonic() - t0:.1f} s): '
                t0 = time.monotonic()   # their traffic may still be queued on the link: the window fills anew
                if not placed:
                    rospy.logwarn(f'migration_decider: {home_note}')
        note += self._settle(t0, req.settle)
        started = time.monotonic()
        try:
            res = self.profile_now(req.probe) if self._wait(self.profile_now) else None
        except (rospy.ServiceException, rospy.ROSException) as exc:
            res = None
            rospy.logwarn(f'migration_decider: no profile from the network monitor: {exc}')
        if res is None:
            profile = Profile(math.nan, math.nan, math.nan, math.nan, 'none', alive=False)
            note += 'no profile (network monitor not answering): '
        else:
            profile = profile_of(res.profile)
            note += '' if res.success else f'probe failed ({res.message}): '
        self.last_profile = (profile, note)
        return profile, home_note + note, time.monotonic() - started

    def _settle(self, t0: float, settle: float) -> str:
        """Wait until ``settle`` s after ``t0`` *and* after the network monitor's periodic profiles began to say
        the cloud answers, the latter at most ``decider.link_wait`` s from now (at a session's start the cloud's
        side and the bridge may still be coming up: a profile taken then knows no RTT). If the cloud went silent
        meanwhile it waits and settles anew, within the same bound. Returns a
        note for the decision's message ('' when the cloud was heard at once)."""
        start = time.monotonic()
        deadline = start + self.link_wait
        while not rospy.is_shutdown():
            with self.lock:
                since = self.alive_since
            if since is None and time.monotonic() < deadline:
                time.sleep(0.1)
                continue
            until = max(t0, since or t0) + settle
            while not rospy.is_shutdown() and time.monotonic() < until:
                time.sleep(0.1)
            with self.lock:
                heard = self.alive_since
            if heard != since and time.monotonic() < deadline:
                continue                          # silent meanwhile: settle anew once heard, within the bound
            if heard is None:
                return f'the network monitor did not hear the cloud for {self.link_wait:g} s: '
            return '' if heard <= start else f'the cloud first heard {heard - start:.1f} s after the request: '
        return ''

    @quiet_at_shutdown
    def _on_decide(self, req) -> DecideResponse:
        profile, note, profile_time = self._profile(req)
        with self.lock:
            try:
                d, hosts, warnings = self.advisor.begin(req.task, req.location, profile, time.monotonic(),
                                                        FORCE_WORD.get(req.force, f'code {req.force}'),
                                                        req.explore)
            except AdvisorError as exc:
                return DecideResponse(ok=False, message=str(exc))
        for w in warnings:
            rospy.logwarn(f'migration_decider: {w}')
        t0 = time.monotonic()
        placed, moved, message, now = self.place(hosts)
        with self.lock:
            self.advisor.placed(time.monotonic(), moved, now)
        if not placed:
            ran = self.advisor.placement_of(req.task, now)
            message += ('; placement not made: ' + (f'the task runs as {ran} and is evaluated as such' if ran else
                                                    'the modules are split, the run is not learned'))
        out = self._message('decided', req.task, req.location, d.decision, d, profile, now)
        out.placed, out.placing_time, out.migrations = placed, time.monotonic() - t0, moved
        out.profile_time = profile_time
        why = {'knn': f'k-NN {d.votes.get(d.decision, 0)} of {self.cfg.decision.k} votes',
               'cold_start': 'cold-start rule', 'explore': f'exploration (policy: {d.policy})',
               'no_profile': 'no usable profile: the robot', 'forced': 'forced'}.get(d.reason, d.reason)
        out.message = (f'{note}{d.decision} ({why}) at RTT {1000 * profile.c_l:.0f} ms, R_bw {profile.r_bw:.3g}; '
                       f'{message}')
        rospy.loginfo(f'migration_decider: {req.task}@{req.location}: {out.message}')
        self.pub.publish(out)
        return DecideResponse(ok=True, message=out.message, decision=out)

    @quiet_at_shutdown
    def _on_evaluate(self, req) -> EvaluateTaskResponse:
        with self.lock:
            running = self.advisor.running
            if running is None:
                return EvaluateTaskResponse(ok=False, message='no task is running (call ~decide first)')
            try:
                status = MISSION_STATUS_WORD.get(req.mission_status, f'code {req.mission_status}')
                row, control = self.advisor.finish(status, req.t_task, req.b_task, time.time(), req.learn)
            except (ConfigError, ValueError) as exc:
                return EvaluateTaskResponse(ok=False, message=str(exc))
        d = running.decision
        out = self._message('evaluated', row.task, row.location, row.decision, d, running.profile,
                            running.history[-1])
        out.placement = row.placement
        out.mission_status, out.t_task, out.b_task, out.value, out.good, out.label = \
            MISSION_STATUS[row.mission_status], row.t_task, row.b_task, row.value, row.good, PLACEMENT[row.label]
        out.learned = self.advisor.learned
        out.message = (f'{row.decision} {row.mission_status}: T {row.t_task:.1f} s (CT {control.ct_mean:.1f}), '
                       f'B {row.b_task:.5f} (CB {control.cb_mean:.5f}), value {row.value:.3f} '
                       f'{"<=" if row.good else ">"} V_r {self.cfg.v_r:g}: label {row.label}'
                       + ('' if out.learned else ' (not learned)'))
        rospy.loginfo(f'migration_decider: {row.task}@{row.location}: {out.message}')
        self.pub.publish(out)
        return EvaluateTaskResponse(ok=True, message=out.message, result=out)

    def _wait(self, proxy) -> bool:
        try:
            proxy.wait_for_service(self.service_timeout)
            return True
        except rospy.ROSException:
            return False


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('migration_decider')
    DeciderNode()
    rospy.spin()
