"""``mission_monitor``: prints the mission's progress and writes the report when the hotspot is found.

Stops the mission (exits; it is ``required`` in mission.launch) ``mission/extra_time`` sim seconds after the
hotspot was declared (the paper ran 50 extra measurements, about 16 s), or at ``mission/timeout``.
Exit status: 0 hotspot found, 3 timeout without a hotspot.
"""
from __future__ import annotations

import math
import os
import sys
import threading
import time
from typing import Dict, List, Optional, Tuple

import rospy
from actionlib_msgs.msg import GoalStatusArray
from nav_msgs.msg import Odometry
from sensor_msgs.msg import BatteryState
from std_srvs.srv import Trigger, TriggerResponse

import cnr_params
from cnr_maps.grid import MapcellGrid
from cnr_maps.mapio import load_map
from cnr_maps.measurements import Measurement, write_tsv
from cnr_mission.core.report import CellSummary, PackReadings, check_store, path_length, render_png, write_summary
from cnr_mission.core.scenario import read_mission
from cnr_mission.core.timeline import write_timeline
from cnr_mission.core.task import COMPLETED, TIMED_OUT
from cnr_msgs.msg import (BatteryEnergy, CellStates, Hotspot, MergedMeasurement, MfgActivity, MigrationEvent,
                          NetworkProfile, Placement, SearchState, StoreForwardStatus, TaskDecision)
from cnr_msgs.srv import Decide, EvaluateTask, GetMeasurements
from cnr_params import ConfigError
from cnr_params.ros import private_section
from cnr_runtime import init_node
from migration_manager.codes import EVENT_MODE_WORD, STEP_WORD
from network_monitor.codes import A_BW_METHOD_WORD
from network_monitor.decider_codes import EVENT_WORD, FORCE, MISSION_STATUS, PLACEMENT_WORD, REASON_WORD
from kestrel_driver.core.field import TemperatureField
from mfg.core.standin import GoalPath, Standstill, read_watch


class MissionMonitor:
    def __init__(self) -> None:
        p = private_section('~')
        mission = read_mission(p)
        self.name = p.section('scenario').string('name')
        self.extra_time, self.timeout = mission.extra_time, mission.timeout
        self.report_dir = os.path.abspath(os.path.expanduser(p.string('report_dir')))
        self.map_file = p.file_path('map_file')
        self.sources = [(s.name, s.x, s.y) for s in TemperatureField.from_section(p.section('temperature_field')).sources]
        self.rtf = p.number('real_time_factor', nonnegative=True)
        self.placement = p.string('placement')
        profile_topic = p.string('network_profile_topic')     # '' on one master: no network to profile
        self.profiles: List[Tuple[float, ...]] = []
        relay_topic = p.string('relay_status_topic')           # '' when no store-and-forward stream runs
        self.relay_drain_timeout = p.number('relay_drain_timeout', nonnegative=True)
        self.relay: Optional[StoreForwardStatus] = None
        self.relay_drained: Optional[StoreForwardStatus] = None     # the status that showed the queue empty
        if relay_topic:
            rospy.Subscriber(relay_topic, StoreForwardStatus, lambda m: setattr(self, 'relay', m), queue_size=2)
        self.relay_expected = bool(relay_topic)
        self.lock = threading.Lock()
        self.trajectory: List[Tuple[float, float]] = []
        self.base_battery = PackReadings()          # the Kobuki base's pack (battery_state)
        self.computer_battery = PackReadings()      # the robot computer's (laptop_charge, the netbook's): B_task
        self.energy_first: Optional[BatteryEnergy] = None
        self.energy_last: Optional[BatteryEnergy] = None
        self.cells: Optional[CellStates] = None
        self.hotspot: Optional[Hotspot] = None
        self.measurements = 0
        self.last_state = ''
        self.activity: Optional[MfgActivity] = None
        self.start_sim: Optional[float] = None
        self.wall0 = time.monotonic()
        rospy.Subscriber('base_pose_ground_truth', Odometry, self._on_pose, queue_size=10)
        rospy.Subscriber('battery_state', BatteryState, self._on_battery, self.base_battery, queue_size=2)
        rospy.Subscriber('laptop_charge', BatteryState, self._on_battery, self.computer_battery, queue_size=2)
        rospy.Subscriber('battery/energy', BatteryEnergy, self._on_energy, queue_size=2)
        rospy.Subscriber('cell_states', CellStates, lambda m: setattr(self, 'cells', m), queue_size=1)
        rospy.Subscriber('hotspot', Hotspot, self._on_hotspot, queue_size=1)
        rospy.Subscriber('merged_measurements', MergedMeasurement, self._on_measurement, queue_size=100)
        rospy.Subscriber('mfg/state', SearchState, self._on_state, queue_size=20)
        self.activity_received = 0.0
        rospy.Subscriber('mfg/activity', MfgActivity, self._on_activity, queue_size=1)
        # the longest standstill with a task pending: move_base's goals and the goal source's heartbeat and
        # mode judged as the robot's stand-in judges them (config/goal_standin.yaml, mfg.core.standin)
        self.goal_path = GoalPath(read_watch(p))
        self.standstill = Standstill()
        rospy.Subscriber('move_base/status', GoalStatusArray, self._on_goal_status, queue_size=5)
        if profile_topic:
            rospy.Subscriber(profile_topic, NetworkProfile, self._on_profile, queue_size=10)
        # migration_manager (two-host runs with --migration): each migration's steps and the placement over time
        self.migrations: List[Dict] = []
        self.published_stamps: List[float] = []     # every merged measurement seen, to check the store against
        self.placements: List[Tuple[float, str, str, int]] = []
        self.current_placement: Dict[str, Tuple[str, int]] = {}
        rospy.Subscriber('/migration_manager/events', MigrationEvent, self._on_migration, queue_size=100)
        rospy.Subscriber('/migration_manager/placement', Placement, self._on_placement, queue_size=10)
        # the network-aware mission: network_monitor's migration_decider places the task's modules at the start,
        # re-decides while the mission runs and evaluates the mission at its end ('' = no decider)
        self.decider = p.string('decider').rstrip('/')
        self.decision_task = p.string('decision_task')
        self.decisions: List[Dict] = []
        self.evaluation: Optional[str] = None
        if self.decider:
            rospy.Subscriber(f'{self.decider}/decisions', TaskDecision, self._on_decision, queue_size=20)
            threading.Thread(target=self._decide, daemon=True).start()
        # ends the mission now (report written as at a timeout; a benchmark that runs the mission as a workload)
        self.finish_requested = threading.Event()
        rospy.Service('~finish', Trigger, self._on_finish)

    def _on_finish(self, _req) -> TriggerResponse:
        self.finish_requested.set()
        return TriggerResponse(success=True, message=f'writing the report to {self.report_dir}')

    def _say(self, text: str) -> None:
        t = rospy.Time.now().to_sec() - (self.start_sim or rospy.Time.now().to_sec())
        # one write per line: print() writes the text and the newline separately, and another thread's
        # output (rospy's log lines) can land between them
        sys.stdout.write(f'[mission {t:7.1f} s] {text}\n')
        sys.stdout.flush()

    def _on_pose(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        with self.lock:
            if self.start_sim is None:
                self.start_sim = msg.header.stamp.to_sec()
            if not self.trajectory or math.hypot(p.x - self.trajectory[-1][0], p.y - self.trajectory[-1][1]) > 0.02:
                self.trajectory.append((p.x, p.y))

    def _on_battery(self, msg: BatteryState, pack: PackReadings) -> None:
        h = self.hotspot
        pack.add(msg, None if h is None else h.header.stamp)

    def _on_activity(self, msg: MfgActivity) -> None:
        self.activity, self.activity_received = msg, rospy.Time.now().to_sec()
        with self.lock:
            self.goal_path.heartbeat(self.activity_received)

    def _on_goal_status(self, msg: GoalStatusArray) -> None:
        with self.lock:
            self.goal_path.status(rospy.Time.now().to_sec(), [(s.goal_id.id, s.status) for s in msg.status_list])

    def _sample_standstill(self) -> None:
        now = rospy.Time.now().to_sec()
        with self.lock:
            since = self.goal_path.standing_since(now)
            rate = self.rtf if self.rtf > 0 else 1.0
            self.standstill.sample(now, since, time.time() - (now - since) / rate if since is not None else 0.0)

    def _on_profile(self, msg: NetworkProfile) -> None:
        if self.start_sim is not None:
            with self.lock:
                self.profiles.append((msg.header.stamp.to_sec() - self.start_sim, float(msg.alive), msg.rtt,
                                      msg.rtt_spread, msg.loss, msg.c_bw, msg.a_bw, msg.r_bw))

    def _sim_since_start(self) -> float:
        now = rospy.Time.now().to_sec()
        return now - (self.start_sim if self.start_sim is not None else now)

    def _on_decision(self, msg: TaskDecision) -> None:
        entry = dict(time=self._sim_since_start(), event=EVENT_WORD[msg.event],
                     decision=PLACEMENT_WORD[msg.decision], reason=REASON_WORD[msg.reason],
                     policy=PLACEMENT_WORD[msg.policy], confidence=msg.confidence, votes_offload=msg.votes_offload,
                     votes_onload=msg.votes_onload, c_l=msg.c_l, r_bw=msg.r_bw, loss=msg.loss,
                     profile_method=A_BW_METHOD_WORD[msg.profile_method], placement=msg.placement,
                     placed=msg.placed, placing_time=msg.placing_time, value=msg.value,
                     label=PLACEMENT_WORD[msg.label], message=msg.message)
        with self.lock:
            self.decisions.append(entry)
        if msg.event == TaskDecision.REDECIDED:
            self._say(f'network-aware: re-decided during the mission: {entry["decision"]} ({msg.message})')

    def _decide(self) -> None:
        """The decision before the task (in a thread: the monitor goes on reporting meanwhile)."""
        try:
            rospy.wait_for_service(f'{self.decider}/decide', 300.0)
            res = rospy.ServiceProxy(f'{self.decider}/decide', Decide)(
                task=self.decision_task, location=self.name, force=FORCE[''], probe=True, explore=True, settle=0.0,
                reuse_profile=False)
            self._say(f'network-aware: {self.decision_task}@{self.name}: ' + res.message)
        except (rospy.ROSException, rospy.ServiceException) as exc:
            if not rospy.is_shutdown():
                self._say(f'network-aware: no decision ({exc}); the modules stay where they started')

    def task_measures(self, found: bool) -> Tuple[str, float, float]:
        """The mission as a task (thesis §4.2.3; the network-aware decision's evaluation and the control runs of
        exp_control.sh): status completed when the hotspot was found, else timed_out; T_task the sim time to the
        hotspot (or the whole mission); B_task the fraction of the robot computer's battery used over the same time
        (to the first reading from the hotspot's time on, 1 Hz), as the thesis read the netbook's."""
        h = self.hotspot
        t = h.header.stamp.to_sec() - self.start_sim if h is not None and self.start_sim is not None \
            else self._sim_since_start()
        return (COMPLETED if found else TIMED_OUT), t, self.computer_battery.used_to_hotspot()

    def evaluate_decision(self, found: bool) -> None:
        """Eq. 4-5 for the mission's decision (network_monitor's ~evaluate), by :meth:`task_measures`."""
        if not self.decider or not any(d['event'] == 'decided' for d in self.decisions):
            return
        status, t, b = self.task_measures(found)
        if not math.isfinite(b):
            self.evaluation = 'not evaluated: no battery reading (the simulator\'s laptop_charge never came)'
            self._say(f'network-aware: {self.evaluation}')
            return
        try:
            res = rospy.ServiceProxy(f'{self.decider}/evaluate', EvaluateTask)(MISSION_STATUS[status], t, b, True)
            self.evaluation = res.message if res.ok else f'not evaluated: {res.message}'
        except (rospy.ROSException, rospy.ServiceException) as exc:
            self.evaluation = f'not evaluated: {exc}'
        self._say(f'network-aware: {self.evaluation}')

    def _on_migration(self, msg: MigrationEvent) -> None:
        if msg.step not in (MigrationEvent.DONE, MigrationEvent.ROLLED_BACK, MigrationEvent.FAILED):
            return
        entry = dict(id=msg.id, time=self._sim_since_start(), module=msg.module, source=msg.source or None,
                     target=msg.target, mode=EVENT_MODE_WORD[msg.mode], outcome=STEP_WORD[msg.step], term=msg.term,
                     downtime=None if math.isnan(msg.downtime) else msg.downtime, message=msg.message)
        with self.lock:
            self.migrations.append(entry)
        self._say(f'migration {msg.id}: {msg.module} {msg.source or "-"} -> {msg.target} ({entry["mode"]}): '
                  f'{entry["outcome"]}'
                  + (f', hand-over {1000 * msg.downtime:.0f} ms' if entry['downtime'] is not None else ''))

    def _on_placement(self, msg: Placement) -> None:
        t = self._sim_since_start()
        with self.lock:
            for module, host, term in zip(msg.modules, msg.hosts, msg.terms):
                if self.current_placement.get(module) != (host, term):
                    self.current_placement[module] = (host, term)
                    self.placements.append((t, module, host, term))

    def _on_energy(self, msg: BatteryEnergy) -> None:
        if self.energy_first is None:
            self.energy_first = msg
        self.energy_last = msg

    def _on_measurement(self, msg: MergedMeasurement) -> None:
        self.measurements += 1
        with self.lock:
            self.published_stamps.append(round(msg.header.stamp.to_sec(), 6))
        if self.measurements % 30 == 0:
            self._say(f'{self.measurements} measurements; latest {msg.temperature:.2f} degC at ({msg.x:.1f}, {msg.y:.1f})')

    def _on_state(self, msg: SearchState) -> None:
        with self.lock:
            self.goal_path.source_mode(rospy.Time.now().to_sec(), msg.mode)
        if msg.message != self.last_state:
            self.last_state = msg.message
            self._say(f'{msg.mode}: {msg.message}')

    def _on_hotspot(self, msg: Hotspot) -> None:
        if self.hotspot is None:
            self.hotspot = msg
            self._say(f'hotspot found in cell {msg.cell_index} (col {msg.col}, row {msg.row}) at '
                      f'({msg.x:.1f}, {msg.y:.1f}), {msg.temperature:.2f} degC; stopping in {self.extra_time:g} s')

    def wait(self) -> bool:
        while not rospy.is_shutdown() and self.start_sim is None:
            time.sleep(0.1)
        while not rospy.is_shutdown():
            now = rospy.Time.now().to_sec()
            self._sample_standstill()
            if self.hotspot is not None and now >= self.hotspot.header.stamp.to_sec() + self.extra_time:
                return True
            if now - self.start_sim > self.timeout:
                self._say(f'timeout after {self.timeout:g} s ' +
                          ('(the hotspot was found before)' if self.hotspot is not None else 'without a hotspot'))
                return self.hotspot is not None
            if self.finish_requested.is_set():
                self._say('asked to finish (~finish): ' + ('hotspot found' if self.hotspot else 'no hotspot yet'))
                return self.hotspot is not None
            time.sleep(0.1)
        return False

    def drain_relay(self) -> None:
        """Nothing made on the robot is left behind: wait (bounded) until the store-and-forward sender's queue
        is empty, i.e. the cloud acknowledged every measurement."""
        if not self.relay_expected:
            return
        self._say(f'waiting up to {self.relay_drain_timeout:g} s for the store-and-forward queue to drain')
        deadline = time.monotonic() + self.relay_drain_timeout
        while not rospy.is_shutdown() and time.monotonic() < deadline:
            r = self.relay
            if r is not None and r.queued == 0 and r.acked_seq == r.last_seq:
                self.relay_drained = r
                self._say(f'store-and-forward drained: {r.appended} stored, all acknowledged')
                return
            time.sleep(0.2)
        r = self.relay
        self._say('store-and-forward NOT drained: ' + ('no status' if r is None else f'{r.queued} still queued'))

    def _standstill_report(self) -> Dict:
        with self.lock:
            s, pending = self.standstill, self.goal_path.pending_since
            t0 = self.start_sim or 0.0
            return dict(longest=s.longest, longest_start=s.longest_wall,
                        longest_start_sim=None if s.longest_since is None else s.longest_since - t0,
                        intervals=s.intervals, total=s.total, open_at_end=s.open,
                        task_pending_from_sim=None if pending is None else pending - t0)

    def write_report(self, found: bool) -> str:
        os.makedirs(self.report_dir, exist_ok=True)
        records: List[Measurement] = []
        try:
            rospy.wait_for_service('local_mapcell_manager/get_measurements', 10)
            res = rospy.ServiceProxy('local_mapcell_manager/get_measurements', GetMeasurements)(-1)
            grid = MapcellGrid.from_cell_states(self.cells) if self.cells and self.cells.cells else None
            for m in res.measurements:           # each carries the cell local_mapcell_manager assigned
                row, col = grid.row_col(m.cell) if grid and 0 <= m.cell < len(grid) else (-1, -1)
                records.append(Measurement(m.header.seq, m.header.stamp.to_sec(), m.x, m.y, m.temperature, m.cell,
                                           row, col, m.pose_stamp.to_sec()))
        except (rospy.ROSException, rospy.ServiceException) as exc:
            rospy.logwarn(f'could not fetch the stored measurements: {exc}')
        write_tsv(os.path.join(self.report_dir, 'measurements.tsv'), records)
        with self.lock:      # read after the store: whatever the store holds was published before this copy
            published = list(self.published_stamps)
        store_check = check_store(published, [r.time for r in records])
        with self.lock:
            profiles = list(self.profiles)
        if profiles:     # the robot's network profile over the mission (network_monitor, thesis Eq. 4-1)
            with open(os.path.join(self.report_dir, 'network_profile.tsv'), 'w') as f:
                f.write('time\talive\trtt\trtt_spread\tloss\tc_bw\ta_bw\tr_bw\n')
                for row in profiles:
                    f.write('\t'.join(f'{v:.6g}' for v in row) + '\n')
        with self.lock:
            migrations, placements = list(self.migrations), list(self.placements)
            decisions = list(self.decisions)
        if decisions:    # each decision with its profile, placement and evaluation (network_monitor)
            keys = list(decisions[0])
            with open(os.path.join(self.report_dir, 'decisions.tsv'), 'w') as f:
                f.write('\t'.join(keys) + '\n')
                for d in decisions:
                    f.write('\t'.join(f'{d[k]:.6g}' if isinstance(d[k], float) else str(d[k]).replace('\t', ' ')
                                      for k in keys) + '\n')
        if placements:   # where each managed module was active over the mission ('' = none: migrating)
            with open(os.path.join(self.report_dir, 'placement.tsv'), 'w') as f:
                f.write('time\tmodule\thost\tterm\n')
                for t, module, host, term in placements:
                    f.write(f'{t:.3f}\t{module}\t{host or "-"}\t{term}\n')
        cells = []
        if self.cells:
            cells = [CellSummary(c.index, c.row, c.col, c.min_x, c.max_x, c.min_y, c.max_y, c.mean_temperature,
                                 c.measurement_count) for c in self.cells.cells]
        with self.lock:
            traj = list(self.trajectory)
        h = self.hotspot
        b0, b1 = self.base_battery.first, self.base_battery.last
        now = rospy.Time.now().to_sec()
        status, t_task, b_task = self.task_measures(found)
        relay = self.relay_drained or self.relay
        summary = dict(
            scenario=self.name, placement=self.placement, found=found,
            task=dict(mission_status=status, t_task=t_task, b_task=None if math.isnan(b_task) else b_task),
            hotspot=None if h is None else dict(cell=h.cell_index, row=h.row, col=h.col, x=h.x, y=h.y,
                                                temperature=h.temperature, search_duration=h.search_duration,
                                                cells_checked=h.cells_checked),
            sim_time_to_find=None if h is None else h.header.stamp.to_sec() - self.start_sim,
            sim_time_start=self.start_sim, sim_time_total=now - self.start_sim, wall_time=time.monotonic() - self.wall0,
            real_time_factor=self.rtf, distance_driven=path_length(traj),
            battery_used_percent=None if b0 is None else 100.0 * (b0.percentage - b1.percentage),
            battery_used_ah=None if b0 is None else b0.charge - b1.charge,
            battery_energy=None if b1 is None else b1.serial_number,
            # battery_used_* and battery_energy: the base's pack (battery_state); the robot computer's (the netbook's):
            computer_battery=self.computer_battery.used(),
            # energy drawn during the mission per consumer [J]: CPU = the robot's processes (its cgroup on the
            # testbed), radio = bytes on the robot's link interface
            energy=None if self.energy_first is None else {
                k: getattr(self.energy_last, k) - getattr(self.energy_first, k)
                for k in ('idle', 'motors', 'cpu', 'radio', 'total', 'cpu_seconds', 'radio_bytes')},
            measurements_taken=len(records) or self.measurements,
            measurements_published_on_robot=self.measurements,
            store_check=store_check,
            network_aware=None if not self.decider else dict(
                task=self.decision_task, decisions_tsv='decisions.tsv', evaluation=self.evaluation,
                decisions=[{k: d[k] for k in ('time', 'event', 'decision', 'reason', 'c_l', 'r_bw', 'placement')}
                           for d in decisions]),
            # the sender's status when the drain was confirmed (the robot goes on measuring until it is shut
            # down: a later status may hold one more, not yet acknowledged), else the last one
            store_and_forward=None if relay is None else dict({
                k: getattr(relay, k) for k in ('stream', 'epoch', 'last_seq', 'acked_seq', 'queued', 'appended',
                                               'sent', 'resent', 'timeouts', 'full', 'rejected')},
                status_at='drain' if relay is self.relay_drained else 'end'),
            network_profile=None if not profiles else dict(
                file='network_profile.tsv', samples=len(profiles),
                alive_fraction=sum(r[1] for r in profiles) / len(profiles)),
            measurements_to_hotspot=None if h is None else sum(1 for r in records if r.time <= h.header.stamp.to_sec()),
            mfg_activity=None if self.activity is None else dict(
                measurements=self.activity.measurements, longest_input_gap=self.activity.longest_input_gap,
                goal_waits=self.activity.goal_waits, goal_wait_total=self.activity.goal_wait_total,
                goal_wait_longest=self.activity.goal_wait_longest, longest_idle=self.activity.longest_idle,
                # the MFG's reports stop reaching the robot when it is cut off (it runs on the cloud): the time
                # since the last one is time the MFG could not act on the robot
                unreachable_at_end=now - self.activity_received),
            # the longest interval with a task pending (from the first move_base goal) in which the robot had no
            # goal pursued and the goal source did not hold it on purpose (mfg.core.standin.GoalPath): s of sim
            # time; longest_start: wall clock (UNIX s), longest_start_sim: s since the mission's start
            standstill=self._standstill_report(),
            heat_sources=[dict(name=n, x=x, y=y) for n, x, y in self.sources],
            migrations=migrations or None,
            placement_over_time=None if not placements else dict(file='placement.tsv', changes=len(placements)))
        if cells:
            occ = extent = None
            try:
                m = load_map(self.map_file)
                occ, b = m.data, m.bounds()
                extent = (b[0], b[2], b[1], b[3])
            except ConfigError as exc:    # the report must still be written
                rospy.logwarn(f'map not drawn: {exc}')
            title = f'{self.name}: ' + (f'hotspot in cell {h.cell_index} after {summary["sim_time_to_find"]:.0f} s'
                                        if h else 'no hotspot found')
            render_png(os.path.join(self.report_dir, 'mapcells.png'), cells, traj, h.cell_index if h else None,
                       title, occ, extent, self.sources)
        try:     # where each module ran, the link, measurements per second, decisions and migrations
            write_timeline(self.report_dir, summary)
        except Exception as exc:    # matplotlib's many errors: the report must still be written
            rospy.logwarn(f'timeline not drawn: {exc}')
        # written last (atomically): its presence means the report is complete
        write_summary(os.path.join(self.report_dir, 'summary.json'), summary)
        return self.report_dir


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('mission_monitor')
    mon = MissionMonitor()
    found = mon.wait()
    if rospy.is_shutdown():
        return
    mon.drain_relay()
    mon.evaluate_decision(found)
    path = mon.write_report(found)
    print(f'[mission] report written to {path}', flush=True)
    rospy.signal_shutdown('mission over')
    sys.exit(0 if found else 3)
