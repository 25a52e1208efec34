"""The mission across two masters on the testbed: robot and cloud, each with its master, bridge and modules.

``run_mission.sh --two-host`` (:mod:`cnr_mission.run`) calls :func:`run`; the same as a command (root: network
namespaces, TUN devices, cgroups)::

    rosrun cnr_mission two_host_mission --scenario FILE --placement NAME|FILE --report-dir DIR
        [--delay MS --rate MBIT --loss PCT | --trace FILE | --link-map FILE] [--port P]

What runs where:

* **robot namespace, outside the CPU cap** (the physical world and the observer): the simulator with its
  battery and map_server, the mission monitor (``world.launch``), the link-map follower or trace player;
* **robot namespace, inside the robot's CPU cgroup** (the robot's computer): the robot's rosmaster, its
  bridge, network_monitor, kestrel_driver and the modules the placement puts on the robot (``host.launch``), and
  goal_standin (mfg package) when mfg is on the cloud or movable: the robot's own patrol goals while mfg gives none;
* **cloud namespace**: the cloud's rosmaster, bridge, network_monitor and the modules placed on the cloud (with
  a map_server of its own when move_base runs there).

With ``--network-aware TASK`` (implies ``--migration``) the robot also runs network_monitor's migration_decider:
the mission monitor asks it to decide for TASK (config/decision.yaml ``tasks``, e.g. patrol: mfg and
global_goal_manager) when the mission starts, the decider re-decides as the link changes, and the monitor asks
for the evaluation (Eq. 4-5) at the end; every decision is in the report (``decisions.tsv``). With
``--task-plan`` the two-host mission runs a plan of tasks instead (:class:`TaskMode`).

With ``--migration`` the modules of config/migration.yaml are managed: a migration agent on each host starts
them, the migration manager (robot, inside the cap) places them where the placement says at the start and moves
them when asked (``migrate.sh``, or the configured rule); both hosts' bridges then carry every name a managed
module may use from either side, and each host's local_mapcell_manager keeps its own store
(``store_<host>.tsv``).

The bridges' allow-lists follow from the placement (``cnr_bringup.placement``). Time: the emulator works in
wall-clock time and two-host runs are real-time runs (real-time factor 1): a delay or rate set on the link is
then the one the nodes see in sim time, and the robot's CPU cap means what it says. The achieved factor
(sim / wall) is in the report (``real_time_factor_achieved``).

Exit status: 0 hotspot found, 3 not found, 2 bad configuration, 130 interrupted, 1 anything else.
"""
from __future__ import annotations

import argparse
import base64
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass
from typing import Dict, List, Optional

import yaml

from cnr_bringup.launcher import EXIT_INTERRUPTED, NOISE
from cnr_bringup.placement import Placement, launch_args, load_catalog, describe
from cnr_harness import Proc, WaitTimeout, wait_until
from cnr_harness.script import require_root
from cnr_mission.core.report import write_summary
from cnr_mission.core.timeline import redraw_timeline
from cnr_mission.options import EXIT_NOT_FOUND, add_link_arguments, add_migration_arguments
from cnr_params.config import EXIT_CONFIG, ConfigError, Section, load_yaml
from cnr_testbed import cpucap
from cnr_testbed.api import Testbed, TestbedError
from cnr_testbed.rosside import RosSide, bridge_config
from migration_manager.cli import parse_placement

DECIDER = '/migration_decider'          # network_monitor's migration_decider on the robot (host.launch decider)


class Stop(Exception):
    """A signal asked the mission to stop."""


def _on_signal(signum, _frame) -> None:
    raise Stop()


class TaskMode:
    """``--task-plan``: instead of the monitoring mission, the task_runner runs a plan of tasks (exp_control.sh,
    exp_campaign.sh). Only the task's modules run, managed by migration_manager (they start on the robot); the
    robot also runs network_monitor's migration_decider with the given training sets and control values."""

    def __init__(self, plan: str, results: str, modules: List[str], training_dir: str, control_values: str) -> None:
        self.plan, self.results, self.modules = plan, results, list(modules)
        self.training_dir, self.control_values = training_dir, control_values

    def world_args(self, testbed_config: str) -> List[str]:
        return [f'task_plan:={self.plan}', f'task_results:={self.results}', f'testbed_config:={testbed_config}']

    def host_args(self, args: List[str]) -> List[str]:
        """host.launch arguments: no monitoring modules; the decider and the task's managed modules."""
        monitoring = ('merger', 'local_mapcell_manager', 'global_goal_manager', 'mfg', 'kestrel_driver')
        out = [a for a in args if a.split(':=')[0] not in monitoring]
        out += [f'{m}:=false' for m in monitoring]
        return out + ['migration_modules:=' + json.dumps(self.modules), 'decider:=true',
                      f'training_dir:={self.training_dir}', f'control_values:={self.control_values}']


class TwoHostMission:
    """Brings up the testbed, the two masters and the three launches; waits for the mission monitor."""

    def __init__(self, ws_config: str, scenario_file: str, map_file: str, start: List[str], placement: Placement,
                 report_dir: str, port: int, link: Dict[str, float], trace: Optional[str],
                 link_map: Optional[str], migration: bool = False, rule: bool = False,
                 task: Optional[TaskMode] = None, network_aware: str = '') -> None:
        self.config = os.path.abspath(ws_config)
        self.scenario_file, self.map_file, self.start = scenario_file, map_file, start
        self.task = task
        self.network_aware = network_aware
        self.training_dir, self.control_values = '', ''      # '' = config/decision.yaml's
        self.view_display, self.record = '', False             # run_mission.sh --view (its display), --record
        self.view_cfg = None
        self.migration = migration or rule or task is not None or bool(network_aware)
        self.rule = rule
        if self.migration:
            from migration_manager.core.config import from_section
            self.migration_cfg = from_section(Section.from_file(os.path.join(ws_config, 'migration.yaml')))
            placement = placement.managed_by(task.modules if task else self.migration_cfg.modules)
        self.placement = placement
        self.report_dir = report_dir
        self.log_dir = os.path.join(report_dir, 'logs')
        self.port = port
        self.link, self.trace, self.link_map = link, trace, link_map
        settings = Section.from_file(os.path.join(ws_config, 'two_host.yaml')).section('two_host')
        self.relay_drain_timeout = settings.number('relay_drain_timeout', nonnegative=True)
        self.robot_master_nice = settings.integer('robot_master_nice', minimum=-20, maximum=19)
        monitors = settings.section('network_monitor')
        self.monitor_settings = {side: dict(monitors.section(side).data) for side in ('robot', 'cloud')}
        self.testbed = Testbed(os.path.join(ws_config, 'testbed.yaml'))
        self.owns_testbed = False
        self.robot: Optional[RosSide] = None
        self.cloud: Optional[RosSide] = None
        self.procs: Dict[str, Proc] = {}
        self.counters0: Optional[Dict] = None
        self.link_log: List[Dict] = []
        self.cpu: Dict = {}

    # -- files each host's launch reads -------------------------------------------------------------------
    def _write_yaml(self, name: str, data: Dict) -> str:
        path = os.path.join(self.log_dir, name)
        with open(path, 'w') as f:
            yaml.safe_dump(data, f, default_flow_style=None, sort_keys=False)
        return path

    def _secret(self) -> str:
        path = os.path.join(self.log_dir, 'bridge.secret')
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, 'w') as f:
            f.write(base64.b64encode(os.urandom(32)).decode() + '\n')
        return path

    def _bridge_config(self, side: RosSide, peer: RosSide, secret: str) -> str:
        """The host's bridge file: this testbed's addresses, the placement's allow-lists, config/'s deny lists."""
        host = load_yaml(os.path.join(self.config, f'bridge_{side.side}.yaml'))
        return bridge_config(side, peer, secret, allow_topics=self.placement.allow('topics'),
                             allow_services=self.placement.allow('services'),
                             deny_topics=host['deny_topics'], deny_services=host['deny_services'])

    def _monitor_overlay(self, side: RosSide, peer: RosSide) -> str:
        return self._write_yaml(f'network_monitor_{side.side}.yaml',
                                dict(self.monitor_settings[side.side], name=side.side, peer=peer.side,
                                     peer_address=peer.address))

    def _robot_cpu(self) -> List[str]:
        """The prefix that runs a command inside the robot's CPU cgroup (cnr_testbed.cpucap; it says in one line
        when no cgroup is available and runs the command uncapped)."""
        return cpucap.run_argv([], self.testbed.robot_cgroup, self.testbed.config_path)

    def _robot_cpu_capacity(self) -> str:
        """The robot cgroup's CPU limit: the battery's ``cpu_capacity`` (a capped robot busy all the time is the
        netbook at full load); '' when the robot runs uncapped (config/battery.yaml's value)."""
        cpus = self.robot_cpu_report().get('limit_cpus')
        return f'{cpus:.6g}' if cpus else ''

    def robot_cpu_report(self) -> Dict:
        """CPU used by the robot's computer (its cgroup) and how often the cap throttled it."""
        try:
            cg = cpucap.CpuCgroup(cpucap.detect(), self.testbed.robot_cgroup)
            if not cg.exists():
                return dict(cgroup=None)
            cpus, period = cg.limit()
            th = cg.throttling()
            return dict(cgroup=self.testbed.robot_cgroup, limit_cpus=cpus, period_us=period,
                        cpu_seconds=cg.usage_seconds(), throttled_periods=th.throttled,
                        periods=th.periods, throttled_seconds=th.throttled_seconds,
                        by_process={k: round(v, 2) for k, v in cg.by_process().items()})
        except (OSError, cpucap.NoCgroup, ValueError) as exc:
            return dict(cgroup=None, problem=str(exc))

    # -- processes -------------------------------------------------------------------------------------
    def _launch(self, side: RosSide, name: str, args: List[str], until: Optional[str] = None,
                prefix: Optional[List[str]] = None) -> Proc:
        argv = list(prefix or []) + ['rosrun', 'cnr_bringup', 'cnr_launch']
        if until:
            argv += ['--until', until]
        proc = side.run(argv + args, name)
        self.procs[name] = proc
        return proc

    def up(self) -> None:
        os.makedirs(self.log_dir, exist_ok=True)
        if self.testbed.running():
            print(f'[two-host] using the running testbed {self.testbed.cfg.name!r}', flush=True)
        else:
            self.testbed.up()
            self.owns_testbed = True
            print(f'[two-host] testbed {self.testbed.cfg.name!r} up: robot {self.testbed.robot_address}, '
                  f'cloud {self.testbed.cloud_address}', flush=True)
        if self.link:
            self.testbed.set('both', **self.link)
        self.counters0 = self.testbed.status()
        self.robot = RosSide(self.testbed, 'robot', port=self.port, log_dir=self.log_dir)
        self.cloud = RosSide(self.testbed, 'cloud', port=self.port, log_dir=self.log_dir)
        self.robot.start_master(use_sim_time=True,
                                prefix=[*self._robot_cpu(), 'nice', '-n', str(self.robot_master_nice)])
        self.cloud.start_master(use_sim_time=True)
        for side in (self.robot, self.cloud):
            # one run id per master, set before its launches start (roslaunch reads it from the master and
            # refuses a second launch whose own id differs)
            side.call('setParam', '/run_id', str(uuid.uuid1()))
        secret = self._secret()
        x, y, a = self.start
        # every launch reads its nodes' configuration from the same directory as this process (--config-dir)
        common = [f'scenario_file:={self.scenario_file}', f'map:={self.map_file}', f'config_dir:={self.config}']
        self.start_viewer()
        self._launch(self.robot, 'world', ['cnr_mission', 'world.launch', *common, f'x:={x}', f'y:={y}', f'a:={a}',
                                           'real_time_factor:=1', f'report_dir:={self.report_dir}',
                                           f'placement:={self.placement.name}',
                                           f'battery_cpu_cgroup:={self.testbed.robot_cgroup}',
                                           f'battery_interface:={self.testbed.cfg.robot_dev}',
                                           f'battery_cpu_capacity:={self._robot_cpu_capacity()}',
                                           'relay_status_topic:=' + ('/store_forward_sender/status'
                                                                     if self.placement.relayed() else ''),
                                           f'relay_drain_timeout:={self.relay_drain_timeout}',
                                           *(self.task.world_args(self.testbed.config_path) if self.task else []),
                                           *([f'decider:={DECIDER}', f'decision_task:={self.network_aware}']
                                             if self.network_aware else []), *self.viz_args()],
                     until='task_runner' if self.task else 'mission_monitor')
        for side, peer in ((self.robot, self.cloud), (self.cloud, self.robot)):
            store = f'store_{side.side}.tsv' if self.migration else 'store.tsv'
            host_args = ['cnr_mission', 'host.launch', f'host:={side.side}', *common,
                         f'store:={os.path.join(self.report_dir, store)}',
                         f'bridge_config:={self._bridge_config(side, peer, secret)}', f'secret_file:={secret}',
                         f'network_monitor_overlay:={self._monitor_overlay(side, peer)}',
                         *launch_args(self.placement, side.side)]
            if side.side == self.deferred_merger:
                host_args = ['merger:=false' if a == 'merger:=true' else a for a in host_args]
            relayed = self.placement.relayed()
            if len(relayed) > 1:
                raise ConfigError(self.placement.name, 'store_forward', 'the two-host launch relays one stream at most')
            for st in relayed:
                host_args += [f'relay_stream:={st.stream}', f'relay_topic:={st.topic}',
                              f'relay_dir:={os.path.join(self.report_dir, "store_forward_" + side.side)}']
            if self.migration:
                start = {m: self.placement.host(m) for m in self.placement.managed}
                host_args += ['migration:=true', 'migration_placement:=' + json.dumps(start),
                              f'migration_rule:={str(self.rule).lower()}',
                              # kept with the report (the default directory is shared by every run)
                              f'migration_log_dir:={os.path.join(self.log_dir, "instances")}']
            if side.side == 'robot':
                host_args.append('kestrel_driver:=true')
                if self.goal_standin:
                    host_args.append('goal_standin:=true')
            elif self.placement.host('move_base') == 'cloud' or 'move_base' in self.placement.managed:
                host_args.append('map_server:=true')
            if self.task:
                host_args = self.task.host_args(host_args)
            elif self.network_aware:
                host_args += ['decider:=true', f'training_dir:={self.training_dir}',
                              f'control_values:={self.control_values}']
            self._launch(side, f'host_{side.side}', host_args,
                         prefix=self._robot_cpu() if side.side == 'robot' else None)
        tb_cli = [sys.executable, '-m', 'cnr_testbed.cli', '--config', self.testbed.config_path]
        if self.trace:
            self.procs['trace'] = self.robot.run(tb_cli + ['trace', self.trace], 'trace')
        if self.link_map:
            self.procs['follow'] = self.robot.run(tb_cli + ['follow', '--map', self.link_map], 'follow')
        if self.deferred_merger:             # after the trace: its time 0 is the mission's start
            self._start_merger_once_stored(common)

    @property
    def goal_standin(self) -> bool:
        """The robot runs goal_standin (mfg package) when its goal source, mfg, may be off the robot: placed on the
        cloud or movable (no mfg runs in task mode)."""
        return self.task is None and (self.placement.host('mfg') != 'robot' or 'mfg' in self.placement.managed)

    @property
    def deferred_merger(self) -> Optional[str]:
        """The merger's host when it must wait for the store: with a managed local_mapcell_manager the store's first
        instance is up only after the migration agents have started it (about a minute on the capped robot); a
        merged measurement made before then would have no store."""
        if self.migration and 'local_mapcell_manager' in self.placement.managed and \
                'merger' not in self.placement.managed:
            return self.placement.host('merger')
        return None

    def active_hosts(self) -> Dict[str, str]:
        """Where each managed module is active now (``migrate --placement`` on the robot; {} if no answer)."""
        try:
            out = subprocess.run(['ip', 'netns', 'exec', self.robot.namespace, 'rosrun', 'migration_manager',
                                  'migrate', '--placement', '--timeout', '3'], env=self.robot.env,
                                 capture_output=True, text=True, timeout=30)
        except subprocess.TimeoutExpired:
            return {}
        return parse_placement(out.stdout)

    def _start_merger_once_stored(self, common: List[str]) -> None:
        """Start the merger once a local_mapcell_manager instance is active, so that every merged measurement the
        robot makes reaches a store (the robot does not move before its managed modules are up either)."""
        host = self.deferred_merger
        side = self.robot if host == 'robot' else self.cloud
        limit = self.migration_cfg.timeouts.start + 60.0
        print(f'[two-host] the merger starts once local_mapcell_manager is active (at most {limit:.0f} s)', flush=True)
        t0 = time.monotonic()

        def store_active() -> str:
            for name, proc in self.procs.items():
                if proc.poll() is not None:
                    raise TestbedError(f'{name} ended with status {proc.poll()} while the modules were starting '
                                       f'(log: {proc.log_path})')
            active = self.active_hosts().get('local_mapcell_manager', '')
            return active if active in ('robot', 'cloud') else ''
        try:
            active = wait_until(store_active, limit, 'local_mapcell_manager active', interval=1.0)
            print(f'[two-host] local_mapcell_manager active on the {active} after {time.monotonic() - t0:.0f} s: '
                  f'starting the merger on the {host}', flush=True)
        except WaitTimeout:
            print(f'[two-host] local_mapcell_manager not active after {limit:.0f} s: starting the merger anyway '
                  f'(measurements made before a store is up are not stored)', flush=True)
        store = os.path.join(self.report_dir, f'store_{host}.tsv')
        self._launch(side, 'merger', ['cnr_mission', 'modules.launch', *common, f'store:={store}', 'merger:=true'],
                     prefix=self._robot_cpu() if host == 'robot' else None)

    # -- run_mission.sh --view / --record: cnr_viz's markers on the robot's master, rviz and rosbag beside it ----
    def viz_args(self) -> List[str]:
        if not (self.view_display or self.record):
            return []
        return ['viz:=true', f'link_map:={self.link_map or ""}']

    def start_viewer(self) -> None:
        from cnr_viz import viewer
        if self.record:
            self.procs['record'] = self.robot.run(viewer.record_argv(self.config, self.report_dir), 'record')
        if self.view_display:        # its window up before the mission starts
            path, _, self.view_cfg = viewer.write_rviz_config(self.config, self.scenario_file, self.log_dir)
            rviz = viewer.open_rviz(lambda: self.robot.run(viewer.rviz_argv(path), 'rviz',
                                                           env={'DISPLAY': self.view_display}),
                                    self.view_display, self.view_cfg)
            if rviz is None:
                print(f'[two-host] rviz ended {self.view_cfg.rviz_attempts} times before its window showed', flush=True)
            else:
                self.procs['rviz'] = rviz

    def save_view(self) -> None:
        """rviz's last view as view.png in the report (it keeps the markers after the mission's nodes stopped)."""
        from cnr_viz.viewer import screenshot
        rviz = self.procs.get('rviz')
        if rviz is None:
            return
        if rviz.poll() is not None:
            print(f'[two-host] rviz ended (status {rviz.poll()}) before the mission; no view.png', flush=True)
            return
        try:
            print(f'[two-host] the last view saved as {screenshot(self.view_display, self.view_cfg, self.report_dir)}',
                  flush=True)
        except Exception as exc:      # Xlib raises its own classes; the report stands without the picture
            print(f'[two-host] no view.png ({exc})', flush=True)

    def watch(self) -> int:
        """Print the world launch's output until the mission monitor ends; the exit status."""
        world = self.procs['world']
        offset = 0
        status: Optional[int] = None
        while status is None:
            time.sleep(0.2)
            offset = self._echo(world.log_path, offset)
            status = world.poll()
            for name, proc in self.procs.items():
                rc = proc.poll()
                if name == 'trace' and rc == 0:       # a trace that has played to its end
                    continue
                if name in ('rviz', 'record'):        # the viewers: closing rviz does not end the mission
                    continue
                if name != 'world' and rc is not None and status is None:
                    print(f'[two-host] {name} ended with status {rc} (log: {proc.log_path})', flush=True)
                    status = EXIT_CONFIG if rc == EXIT_CONFIG else 1
            self._sample_link()
        self._echo(world.log_path, offset)
        return status

    def _sample_link(self) -> None:
        if not self.link_log or time.monotonic() - self.link_log[-1]['t_mono'] >= 1.0:
            try:
                st = self.testbed.status()
            except OSError:
                return
            self.link_log.append(dict(t_mono=time.monotonic(), up=st['up'], down=st['down']))

    @staticmethod
    def _echo(path: str, offset: int) -> int:
        try:
            with open(path, 'rb') as f:
                f.seek(offset)
                data = f.read()
        except FileNotFoundError:
            return offset
        end = data.rfind(b'\n') + 1
        for line in data[:end].decode(errors='replace').splitlines():
            if not NOISE.match(line):
                print(line, flush=True)
        return offset + end

    def down(self) -> None:
        self.cpu = self.robot_cpu_report()
        procs = list(self.procs.values())[::-1]
        for proc in procs:              # every launch shuts down at the same time, then each is awaited
            if proc.alive():
                try:
                    os.killpg(proc.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        for proc in procs:
            proc.stop()
        for side in (self.cloud, self.robot):
            if side is not None:
                side.stop()
        if self.owns_testbed:
            self.testbed.down()

    def link_report(self) -> Dict:
        """Link conditions over time and bytes carried, from the emulator's counters."""
        rows = []
        t0 = self.link_log[0]['t_mono'] if self.link_log else 0.0
        for s in self.link_log:
            rows.append(dict(t=round(s['t_mono'] - t0, 2),
                             **{f'{d}_{k}': s[d]['conditions'][k] for d in ('up', 'down')
                                for k in ('delay', 'rate', 'loss', 'outage')},
                             up_bytes=s['up']['counters']['bytes_delivered'],
                             down_bytes=s['down']['counters']['bytes_delivered']))
        path = os.path.join(self.report_dir, 'link.tsv')
        if rows:
            with open(path, 'w') as f:
                f.write('\t'.join(rows[0]) + '\n')
                for r in rows:
                    f.write('\t'.join(str(v) for v in r.values()) + '\n')
        first, last = (self.link_log[0], self.link_log[-1]) if self.link_log else (None, None)
        carried = {d: (last[d]['counters']['bytes_delivered'] - first[d]['counters']['bytes_delivered'])
                   if first else None for d in ('up', 'down')}
        return dict(bytes_up=carried['up'], bytes_down=carried['down'], link_tsv='link.tsv' if rows else None,
                    changes=sum(1 for a, b in zip(self.link_log, self.link_log[1:])
                                if a['up']['conditions'] != b['up']['conditions']))


def amend_summary(report_dir: str, extra: Dict) -> None:
    """Add the two-host section to the monitor's summary.json (rewritten atomically)."""
    path = os.path.join(report_dir, 'summary.json')
    try:
        with open(path) as f:
            summary = json.load(f)
    except (OSError, ValueError):
        return
    summary.update(extra)
    write_summary(path, summary)


@dataclass
class TwoHostOptions:
    """What a two-host run is asked to do (``two_host_mission``'s options; ``run_mission.sh`` fills it in)."""
    config_dir: str
    scenario: str
    map: str
    start: List[str]
    placement: str
    report_dir: str
    port: int
    delay: Optional[float] = None
    rate: Optional[float] = None
    loss: Optional[float] = None
    trace: Optional[str] = None
    link_map: Optional[str] = None
    migration: bool = False
    rule: bool = False
    network_aware: str = ''
    task_plan: Optional[str] = None
    task_results: Optional[str] = None
    training_dir: str = ''
    control_values: str = ''
    view: str = ''                  # the X display rviz opens on ('' = none)
    record: bool = False            # rosbag of the mission into the report


def parse_args(argv: Optional[List[str]]) -> TwoHostOptions:
    ap = argparse.ArgumentParser(prog='two_host_mission', description=__doc__.split('\n')[0])
    ap.add_argument('--config-dir', required=True, help='the workspace config/ folder')
    ap.add_argument('--scenario', required=True, help='scenario YAML')
    ap.add_argument('--map', required=True, help='map YAML (checked by check_scenario)')
    ap.add_argument('--start', nargs=3, required=True, metavar=('X', 'Y', 'YAW'))
    ap.add_argument('--placement', required=True, help='a name in config/placements.yaml or a YAML file')
    ap.add_argument('--report-dir', required=True)
    ap.add_argument('--port', type=int, required=True, help='master port in both namespaces')
    add_link_arguments(ap)
    add_migration_arguments(ap)
    task = ap.add_argument_group('task mode (exp_control.sh, exp_campaign.sh) and --network-aware')
    task.add_argument('--task-plan', help='run this plan of tasks (cnr_mission.core.task) instead of the mission')
    task.add_argument('--task-results', help='results TSV the runs are appended to (resumes after its last run)')
    task.add_argument('--training-dir', default='', help="the decider's training sets ('' = config/decision.yaml's)")
    task.add_argument('--control-values', default='', help="the tasks' control values ('' = config/decision.yaml's)")
    view = ap.add_argument_group('watching (run_mission.sh --view, --record)')
    view.add_argument('--view', default='', metavar='DISPLAY', help="rviz on this X display, attached to the robot's "
                      "master (cnr_viz's markers); its last view is saved as view.png in the report")
    view.add_argument('--record', action='store_true', help='rosbag of the mission into mission.bag in the report')
    return TwoHostOptions(**vars(ap.parse_args(argv)))


def task_mode(args: TwoHostOptions) -> Optional[TaskMode]:
    """The task mode of ``--task-plan`` (ConfigError for a bad plan or task)."""
    if not args.task_plan:
        return None
    from cnr_mission.core.task import load_plan
    from network_monitor.core.decision_config import load_decision_config
    if not args.task_results:
        raise ConfigError('two_host_mission', '--task-results', 'required with --task-plan')
    plan = load_plan(args.task_plan)
    cfg = load_decision_config(os.path.join(args.config_dir, 'decision.yaml'))
    for task in plan.tasks:
        if task not in cfg.tasks:
            raise ConfigError(args.task_plan, 'task', f'{task!r} is not a task of config/decision.yaml '
                                                      f'({", ".join(cfg.tasks)})')
    modules = list(dict.fromkeys(m for task in plan.tasks for m in cfg.tasks[task]))   # every task's
    return TaskMode(os.path.abspath(args.task_plan), os.path.abspath(args.task_results), modules,
                    os.path.abspath(args.training_dir) if args.training_dir else '',
                    os.path.abspath(args.control_values) if args.control_values else '')


def network_aware(args: TwoHostOptions) -> str:
    """The task of ``--network-aware`` after checking it against config/decision.yaml ('' = none)."""
    if not args.network_aware:
        return ''
    from network_monitor.core.decision_config import load_decision_config
    cfg = load_decision_config(os.path.join(args.config_dir, 'decision.yaml'))
    if args.network_aware not in cfg.tasks:
        raise ConfigError('two_host_mission', '--network-aware', f'{args.network_aware!r} is not a task of '
                                                                 f'config/decision.yaml ({", ".join(cfg.tasks)})')
    if args.task_plan:
        raise ConfigError('two_host_mission', '--network-aware', 'not with --task-plan (the plan decides itself)')
    return args.network_aware


def main(argv: Optional[List[str]] = None) -> int:
    return run(parse_args(argv))


def run(args: TwoHostOptions) -> int:
    """Run the two-host mission (or task plan) ``args`` asks for; the exit status."""
    try:
        placement = load_catalog(os.path.join(args.config_dir, 'placements.yaml')).placement(args.placement)
    except ConfigError as exc:
        print(f'two_host_mission: {exc}', file=sys.stderr)
        return EXIT_CONFIG
    link = {k: v for k, v in (('delay', args.delay), ('rate', args.rate)) if v is not None}
    if args.loss is not None:
        if not 0 <= args.loss <= 100:
            print(f'two_host_mission: --loss must be 0..100 %, got {args.loss}', file=sys.stderr)
            return EXIT_CONFIG
        link['loss'] = args.loss / 100.0
    require_root('two_host_mission', 'network namespaces, TUN devices, cgroups')
    try:
        mission = TwoHostMission(args.config_dir, args.scenario, args.map, args.start, placement, args.report_dir,
                                 args.port, link, args.trace, args.link_map, args.migration, args.rule,
                                 task_mode(args), network_aware(args))
        mission.training_dir = os.path.abspath(args.training_dir) if args.training_dir else ''
        mission.control_values = os.path.abspath(args.control_values) if args.control_values else ''
        mission.view_display, mission.record = args.view, args.record
    except ConfigError as exc:
        print(f'two_host_mission: {exc}', file=sys.stderr)
        return EXIT_CONFIG
    print(describe(mission.placement), flush=True)
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    status = 1
    wall0 = time.monotonic()
    try:
        mission.up()
        status = mission.watch()
        mission.save_view()
    except Stop:
        status = EXIT_INTERRUPTED
    except (TestbedError, ConfigError) as exc:
        print(f'two_host_mission: {exc}', file=sys.stderr)
        status = EXIT_CONFIG if isinstance(exc, ConfigError) else 1
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            mission.down()
        finally:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if status in (0, EXIT_NOT_FOUND) and mission.task is None:
        amend_summary(args.report_dir, dict(
            two_host=dict(placement=placement.name, hosts=placement.as_dict(), migration=mission.migration, rule=args.rule,
                          network_aware=args.network_aware or None,
                          managed=list(mission.placement.managed),
                          bridged_topics=mission.placement.allow('topics'),
                          bridged_services=mission.placement.allow('services'),
                          relayed=[s.topic for s in mission.placement.relayed()],
                          link_set=dict(link, trace=args.trace, link_map=args.link_map),
                          wall_time_total=time.monotonic() - wall0, robot_cpu=mission.cpu,
                          **mission.link_report())))
        redraw_timeline(args.report_dir)     # with the placement's hosts (a fixed placement has no placement.tsv)
    return status
