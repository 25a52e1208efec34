"""Migration downtime on the testbed (needs root).

    launch_scripts/bench_migration.sh [--runs 10] [--rtts 0,50,100] [--modules a,b] [--modes cold,hot]
                                      [--cutoff-trials 3] [--standbys cold,warm] [--settle 3] [--out DIR]
                                      [--soak SECONDS] [--soak-link 100,0.05] [--port 11411]
                                      [--config-dir DIR]   (default config/; e.g. a copy with robot_cpu off)
                                      [--slowdown S]       (the robot capped at 1/S CPU, on a copy in the scratch)

Uses the default testbed (robot/cloud namespaces), so run nothing else on it meanwhile. Takes about an hour with
the defaults (cold migrations wait for the clone to start on the capped robot).

Runs the two-host mission with ``--migration`` (every module of config/migration.yaml starts on the robot;
corridor scenario with a long timeout so the robot keeps patrolling), a migration_probe on the robot (the
consumer's view: every output and its instance, 20 global-goal requests a second, move_base's results), and,
for each RTT (set as two one-way halves) x module x mode, ``--runs`` round trips robot -> cloud -> robot through
``migrate``. Hot migrations first start a standby on the target and wait until it is warm. Then, per module,
``--cutoff-trials`` times for each of ``--standbys``: the module on the cloud, the link cut, the time until the
robot's instance is active (its status's stamp), promoted (the manager's placement) and its output is back; the
robot's instance is a warm standby started before the cut, or (cold) none. ``--soak S``: then every module on
the cloud, the link at ``--soak-link`` (RTT ms, loss fraction, both directions) for S seconds: how often a
module failed over (its term moved) and how often the cloud instance's lease lapsed (the probe's ``lapsed``
rows; the instances' logs). At the end: measurements lost (merger's output vs the store) and goals aborted
(move_base results). Writes docs/results/migration_hot/, migration_cold/ (by --modes; both: migration/) or
DIR: results.tsv, failover.tsv, soak.tsv and the page README.md; the rows as measured, the mission's report and
logs and the probe's rows go to bench_results/<that experiment>/. ``--runs 0 --cutoff-trials N --standbys warm
--soak 600`` measures failover and its absence on a lossy link only.
"""
from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import re
import subprocess
import sys
import time
from typing import Dict, List, Optional

import yaml

from cnr_benchmarks import cli, report
from cnr_benchmarks import results as results_page
from migration_manager.cli import parse_placement
from migration_manager.codes import ROLE_WORD
from cnr_benchmarks.core.migration import (OUTPUT_TOPIC, Group, group_results, handover_downtime, handover_gap,
                                           output_flowing, output_period, read_probe, stray_outputs)

# a module counts as working when its output came this recently [s] (move_base: a goal is being driven)
FLOWING_WITHIN = {'move_base': 0.3, 'local_mapcell_manager': 1.5, 'mfg': 2.5, 'global_goal_manager': 0.5}

COLUMNS = ['rtt_ms', 'module', 'mode', 'direction', 'run', 'outcome', 'manager_downtime', 'consumer_gap', 'downtime',
           'stray', 'duration', 'term']
FAILOVER_COLUMNS = ['rtt_ms', 'module', 'standby', 'trial', 'active_after', 'promoted_after', 'output_after',
                    'outcome']
SOAK_COLUMNS = ['module', 'seconds', 'rtt_ms', 'loss', 'term_before', 'term_after', 'host_after', 'failovers',
                'lapses', 'lapses_logged']
RESULT = re.compile(r'migration (\d+): (\S+) -> (\S+): (\S+) \(term (\d+), ([\d.]+) s(?:; hand-over (\d+) ms)?\)')



class MissionEnded(RuntimeError):
    """The two-host mission under the bench exited: nothing more can be measured."""

class Bench:
    def __init__(self, args: argparse.Namespace) -> None:
        from cnr_testbed.api import Testbed
        from cnr_testbed.rosside import RosSide
        self.args = args
        self.out = os.path.abspath(args.scratch)
        os.makedirs(self.out, exist_ok=True)
        self.cfg_dir = os.path.abspath(args.config_dir)
        self.tb = Testbed(os.path.join(self.cfg_dir, 'testbed.yaml'))
        self.robot = RosSide(self.tb, 'robot', port=args.port, log_dir=os.path.join(self.out, 'logs'))
        self.cloud = RosSide(self.tb, 'cloud', port=args.port, log_dir=os.path.join(self.out, 'logs'))
        self.sides = {'robot': self.robot, 'cloud': self.cloud}
        self.mission = None
        self.probe_file = os.path.join(self.out, 'probe.tsv')

    # ---------------------------------------------------------------- helpers
    def ns(self, side: str, *argv: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
        s = self.sides[side]
        try:
            return subprocess.run(['ip', 'netns', 'exec', s.namespace, *argv], env=s.env, capture_output=True,
                                  text=True, timeout=timeout)
        except subprocess.TimeoutExpired:       # e.g. rostopic echo on a topic nobody publishes yet
            return subprocess.CompletedProcess(argv, 124, '', f'timed out after {timeout:g} s')

    def placement(self) -> Dict[str, str]:
        out = self.ns('robot', 'rosrun', 'migration_manager', 'migrate', '--placement', '--timeout', '5', timeout=60)
        return parse_placement(out.stdout)

    def terms(self) -> Dict[str, int]:
        """Each module's term (``migrate --placement``: module host term N ...)."""
        out = self.ns('robot', 'rosrun', 'migration_manager', 'migrate', '--placement', '--timeout', '5', timeout=60)
        return {r[0]: int(r[3]) for r in (line.split() for line in out.stdout.splitlines())
                if len(r) >= 4 and r[2] == 'term' and r[3].isdigit()}

    def role(self, module: str, side: str) -> str:
        out = self.ns(side, 'rostopic', 'echo', '-n', '1', f'/migration/{module}/{side}/status', timeout=15)
        try:
            doc = yaml.safe_load(out.stdout.split('---')[0]) if out.returncode == 0 else {}
            return ROLE_WORD.get(doc.get('role'), '')
        except (yaml.YAMLError, AttributeError):
            return ''

    def wait(self, what: str, condition, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            if self.mission is not None and not self.mission.alive():
                raise MissionEnded(f'the mission ended (exit {self.mission.poll()}, see {self.out}/mission.log)')
            time.sleep(0.5)
        report.progress(f'  (gave up waiting for {what} after {timeout:.0f} s)')
        return False

    def set_rtt(self, rtt_ms: float) -> None:
        self.tb.set('both', delay=rtt_ms / 2.0, outage=False)

    # ---------------------------------------------------------------- the run
    def start(self) -> None:
        scenario = yaml.safe_load(open(os.path.join(self.cfg_dir, 'scenarios', 'corridor.yaml')))
        scenario['mission']['timeout'] = 6 * 3600.0
        scenario['mission']['extra_time'] = 6 * 3600.0
        path = os.path.join(self.out, 'scenario.yaml')
        with open(path, 'w') as f:
            yaml.safe_dump(scenario, f)
        line = subprocess.run(['rosrun', 'cnr_mission', 'check_scenario', path], capture_output=True, text=True,
                              check=True).stdout.split()
        _name, map_file, x, y, a = line
        from cnr_harness import Proc
        report_dir = os.path.join(self.out, 'mission')
        report.move_aside(report_dir)
        self.mission = Proc(['rosrun', 'cnr_mission', 'two_host_mission', '--config-dir', self.cfg_dir,
                             '--scenario', path, '--map', map_file, '--start', x, y, a, '--placement', 'all_robot',
                             '--report-dir', report_dir, '--port', str(self.args.port), '--migration'],
                            os.path.join(self.out, 'mission.log'))
        report.progress(f'two-host mission with --migration starting (log {self.out}/mission.log)')
        modules = self.args.modules
        if not self.wait('every module active on the robot', lambda: not self.mission.alive() or all(
                self.placement().get(m) == 'robot' for m in modules), 300) or not self.mission.alive():
            raise RuntimeError(f'the modules did not come up (see {self.out}/mission.log and the report logs)')
        self.robot.call('setParam', '/migration_probe', dict(
            topics=sorted({t for m, t in OUTPUT_TOPIC.items() if t.startswith('/')} | {'/merged_measurements'}),
            next_goal_rate=20.0, status_modules=list(OUTPUT_TOPIC), hosts=['robot', 'cloud'], out=self.probe_file))
        self.robot.run(['rosrun', 'migration_manager', 'migration_probe'], 'probe')
        report.progress('all modules active on the robot; probe running')

    def migrate(self, module: str, target: str, mode: str) -> Dict:
        """Order a migration; mode '' = the module's default (hot if it keeps a hot standby)."""
        t0 = time.time()
        res = self.ns('robot', 'rosrun', 'migration_manager', 'migrate', module, target,
                      *(['--mode', mode] if mode else []), timeout=180)
        t1 = time.time()
        m = RESULT.search(res.stdout)
        out = dict(t0=t0, t1=t1, outcome='error', manager_downtime='', term='', duration=t1 - t0,
                   text=(res.stdout + res.stderr).strip())
        if m:
            out.update(outcome=m.group(4), term=m.group(5), duration=float(m.group(6)),
                       manager_downtime='' if m.group(7) is None else float(m.group(7)) / 1000.0)
        return out

    def wait_flowing(self, module: str) -> bool:
        """Order a migration while the module is producing output, so the consumer's gap is the hand-over's."""
        return self.wait(f'{module} producing output', lambda: output_flowing(
            read_probe(self.probe_file, tail_bytes=65536), module, time.time(), FLOWING_WITHIN[module]), 90)

    def warm_standby(self, module: str, host: str) -> bool:
        """A standby of the module on the host, warm: the module's dormant instance there woken (config/migration.yaml
        ``dormant``: a retired move_base sleeps on the robot), else one started by the host's agent."""
        if self.role(module, host) == 'dormant':
            res = self.ns('robot', 'rosservice', 'call', f'/migration/{module}/{host}/control', '{command: wake}',
                          timeout=30)
            if res.returncode != 0 or 'ok: True' not in res.stdout:
                report.progress(f'  (waking the dormant {module} on {host} failed: '
                                f'{(res.stdout + res.stderr).strip()[-200:]})')
            return self.wait(f'a warm {module} standby on {host}', lambda: self.role(module, host) == 'standby', 120)
        res = self.ns('robot', 'rosservice', 'call', f'/migration/agents/{host}/command', 'start', module, timeout=30)
        if res.returncode != 0 or 'ok: True' not in res.stdout:
            report.progress(f'  (the {host} agent did not start a {module} standby: {(res.stdout + res.stderr).strip()[-200:]})')
        return self.wait(f'a warm {module} standby on {host}', lambda: self.role(module, host) == 'standby', 120)

    def round_trips(self, results: report.TsvLog, rtt: float) -> None:
        for module in self.args.modules:
            for mode in self.args.modes:
                for run in range(1, self.args.runs + 1):
                    for source, target in (('robot', 'cloud'), ('cloud', 'robot')):
                        if mode == 'hot' and not self.warm_standby(module, target):
                            results.row(rtt_ms=rtt, module=module, mode=mode, direction=f'{source}->{target}', run=run,
                                        outcome='no_standby', manager_downtime='', consumer_gap='', downtime='', stray='',
                                        duration=0.0, term='')
                            continue
                        self.wait_flowing(module)
                        r = self.migrate(module, target, mode)
                        time.sleep(self.args.settle)
                        rows = read_probe(self.probe_file)
                        gap = handover_gap(rows, module, source, target, r['t0'], r['t1'])
                        down = handover_downtime(rows, module, source, target, r['t0'], r['t1'])
                        stray = stray_outputs(rows, module, source, target, r['t0'], r['t1'])
                        results.row(rtt_ms=rtt, module=module, mode=mode, direction=f'{source}->{target}', run=run,
                                    outcome=r['outcome'], manager_downtime=r['manager_downtime'],
                                    consumer_gap='' if gap is None else gap, downtime='' if down is None else down,
                                    stray=stray,
                                    duration=r['duration'], term=r['term'])
                        report.progress(f'RTT {rtt:g} ms {module} {mode} {source}->{target} #{run}: {r["outcome"]}, '
                                        f'hand-over (manager) {r["manager_downtime"]}, downtime '
                                        f'{"–" if down is None else f"{1000 * down:.0f} ms"}, consumer gap '
                                        f'{"–" if gap is None else f"{1000 * gap:.0f} ms"}, {r["duration"]:.1f} s')
                        if r['outcome'] != 'done':
                            report.progress(f'    {r["text"][-300:]}')

    def cutoffs(self, failover: report.TsvLog, rtt: float) -> None:
        """The module active on the cloud, the link cut: the robot takes it over with the newest replicated state,
        from a cold start (no standby on the robot) and from a warm standby started there before the cut."""
        for module in self.args.modules:
            for standby in self.args.standbys:
                for trial in range(1, self.args.cutoff_trials + 1):
                    self.cutoff(failover, rtt, module, standby, trial)

    def cutoff(self, failover: report.TsvLog, rtt: float, module: str, standby: str, trial: int) -> None:
        key = dict(rtt_ms=rtt, module=module, standby=standby, trial=trial)
        if self.placement().get(module) != 'cloud':
            self.wait_flowing(module)
            if self.migrate(module, 'cloud', '')['outcome'] != 'done':
                failover.row(**key, active_after='', promoted_after='', output_after='', outcome='not_on_cloud')
                return
        if standby == 'warm' and not self.warm_standby(module, 'robot'):
            failover.row(**key, active_after='', promoted_after='', output_after='', outcome='no_standby')
            return
        if standby == 'cold' and self.role(module, 'robot') == 'standby':      # a hot standby kept there
            self.ns('robot', 'rosservice', 'call', '/migration/agents/robot/command', 'stop', module, timeout=30)
            self.wait(f'no {module} standby on the robot', lambda: self.role(module, 'robot') != 'standby', 60)
        time.sleep(self.args.settle)
        self.wait_flowing(module)
        self.tb.set('both', outage=True)
        t_cut = time.time()
        ok = self.wait(f'{module} promoted on the robot', lambda: self.placement().get(module) == 'robot', 150)
        promoted = time.time() - t_cut if ok else ''
        time.sleep(2.0)
        rows = read_probe(self.probe_file, tail_bytes=1 << 22)
        topic = OUTPUT_TOPIC[module]
        first = next((r.time for r in rows if r.topic == topic and r.time > t_cut and r.ok and
                      (topic == 'next_goal' or r.instance == f'{module}@robot')), None)
        active = next((r.time for r in rows if r.topic == 'active' and r.time > t_cut
                       and r.instance == f'{module}@robot'), None)
        self.set_rtt(rtt)
        failover.row(**key, active_after='' if active is None else active - t_cut, promoted_after=promoted,
                     output_after='' if first is None else first - t_cut, outcome='promoted' if ok else 'timeout')
        report.progress(f'RTT {rtt:g} ms cut-off {module} ({standby} standby on the robot) #{trial}: active after '
                        f'{"–" if active is None else f"{active - t_cut:.2f} s"}, promoted (placement) after '
                        f'{"–" if promoted == "" else f"{promoted:.2f} s"}, output back after '
                        f'{"–" if first is None else f"{first - t_cut:.2f} s"}')
        self.wait(f'the cloud instance of {module} to step down', lambda: self.role(module, 'cloud') != 'active', 60)
        time.sleep(self.args.settle)

    def soak(self, out: report.TsvLog) -> None:
        """Every module of --modules active on the cloud, the link at --soak-link for --soak seconds: failovers (a
        module's term moved or it left the cloud) and lapses of the cloud instances' leases (the probe's
        ``lapsed`` rows, stamped by the instance; and ``lease lapsed`` lines in the instances' logs)."""
        rtt, loss = self.args.soak_link
        modules = self.args.modules
        for module in modules:
            if self.placement().get(module) != 'cloud' and self.migrate(module, 'cloud', '')['outcome'] != 'done':
                report.progress(f'  (soak: {module} could not be moved to the cloud)')
        time.sleep(self.args.settle)
        before = self.terms()
        self.tb.set('both', delay=rtt / 2.0, loss=loss, outage=False)
        t0 = time.time()
        report.progress(f'soak: {", ".join(modules)} on the cloud, RTT {rtt:g} ms, loss {100 * loss:g} % for '
                        f'{self.args.soak:g} s (terms {before})')
        self.wait('the soak to end', lambda: time.time() - t0 >= self.args.soak, self.args.soak + 5)
        t1 = time.time()
        self.tb.set('both', delay=0.0, loss=0.0, outage=False)
        after, hosts = self.terms(), self.placement()
        rows = read_probe(self.probe_file)
        logged = lapses_logged(os.path.join(self.out, 'mission', 'logs', 'instances'), t0, t1)
        for module in modules:
            lapses = sum(1 for r in rows if r.topic == 'lapsed' and r.instance == f'{module}@cloud'
                         and t0 <= r.time <= t1)
            moved = after.get(module, -1) != before.get(module, -2) or hosts.get(module) != 'cloud'
            out.row(module=module, seconds=round(t1 - t0, 1), rtt_ms=rtt, loss=loss, term_before=before.get(module, ''),
                    term_after=after.get(module, ''), host_after=hosts.get(module, ''),
                    failovers=(after.get(module, 0) - before.get(module, 0) + 1) // 2 if moved else 0, lapses=lapses,
                    lapses_logged=logged.get(f'{module}@cloud', 0))
            report.progress(f'soak {module}: terms {before.get(module)} -> {after.get(module)}, on '
                            f'{hosts.get(module)}, {lapses} lapses ({logged.get(f"{module}@cloud", 0)} logged)')

    def stop(self) -> Dict:
        """Ends the mission through the monitor's ~finish (it writes its report, with the store check), then stops
        what is left."""
        if self.mission is None:
            return {}
        path = os.path.join(self.out, 'mission', 'summary.json')
        if self.mission.alive():
            res = self.ns('robot', 'rosservice', 'call', '/mission_monitor/finish', timeout=60)
            if res.returncode == 0:
                self.wait('the mission report', lambda: os.path.exists(path), 180)
            else:
                report.progress(f'  (could not end the mission through ~finish: {res.stderr.strip()[-200:]})')
        self.mission.stop(timeout=120)
        self.robot.stop()                      # the probe (it outlived the bench before)
        return json.load(open(path)) if os.path.exists(path) else {}


LAPSE_LINE = re.compile(r'\[(?:WARN|WARNING)\] \[(\d+\.\d+)[^\]]*\]: (\S+@\S+): lease lapsed')


def lapses_logged(log_dir: str, t0: float, t1: float) -> Dict[str, int]:
    """instance -> ``lease lapsed`` lines in the instances' logs (``log_dir``) stamped between t0 and t1."""
    counts: Dict[str, int] = {}
    if not os.path.isdir(log_dir):
        return counts
    for name in os.listdir(log_dir):
        with open(os.path.join(log_dir, name), errors='replace') as f:
            for line in f:
                m = LAPSE_LINE.search(line)
                if m and t0 <= float(m.group(1)) <= t1:
                    counts[m.group(2)] = counts.get(m.group(2), 0) + 1
    return counts


def write_markdown(out: str, args: argparse.Namespace, results: List[Dict], failovers: List[Dict],
                   summary: Dict, aborted: int, started: str, probe_file: str, soaks: List[Dict]) -> str:
    """The page README.md with results.tsv and failover.tsv in ``out``; returns the page."""
    from cnr_benchmarks.core.stats import percentile
    header = list(Group.HEADER)
    probe = read_probe(probe_file) if os.path.exists(probe_file) else []
    periods = {m: output_period(probe, m) for m in args.modules}
    lines = [f'Started {started}.']
    if results:
        lines += ['', 'Downtime: the old instance closed its outputs (its frozen status\'s stamp) -> the first '
                 'output of the new one arrives at the consumer on the robot (migration_probe; one clock for both '
                 'hosts on the testbed). Consumer gap: last output of the old instance to the first of the new one, measured on the '
                 'robot; it holds the module\'s own output period too. Manager: freeze answered -> the target active '
                 '(its promotion answered, or its first lease granted). ms; median / p95 / max over both directions. '
                 '"gaps" = migrations whose gap could be told (move_base: not when its goal ended during the '
                 'hand-over). Without any migration a consumer already sees the output period between two outputs: '
                 + ', '.join(f'{m} {1000 * p:.0f} ms' for m, p in periods.items() if p == p) + '.', '',
                 report.markdown_table(['RTT ms', 'module', 'mode', *header],
                                       [g.row() for g in group_results(results, ('rtt_ms', 'module', 'mode'))]),
                 '', 'By direction:', '',
                 report.markdown_table(['RTT ms', 'module', 'mode', 'direction', *header],
                                       [g.row() for g in group_results(results, ('rtt_ms', 'module', 'mode',
                                                                                  'direction'))])]
    if failovers:
        def column(v: List[Dict], key: str) -> List[float]:
            return [float(x[key]) for x in v if x.get(key)]
        lines += ['', 'Cut-off while active on the cloud: seconds from the cut until the robot instance is active '
                  '(its status\'s stamp) / promoted (the manager\'s placement, polled) / its output is back; standby '
                  '= what ran on the robot before the cut (cold: nothing, the instance is started then).', '',
                  report.markdown_table(['RTT ms', 'module', 'standby', 'trials', 'active p50', 'active max',
                                         'promoted p50', 'output p50', 'output max'], [
                      [*k, len(v), percentile(column(v, 'active_after'), 50),
                       max(column(v, 'active_after') or [math.nan]),
                       percentile(column(v, 'promoted_after'), 50), percentile(column(v, 'output_after'), 50),
                       max(column(v, 'output_after') or [math.nan])]
                      for k, v in sorted(report.group(failovers, 'rtt_ms', 'module', 'standby').items())])]
    if soaks:
        lines += ['', 'Soak: the modules active on the cloud, the link lossy for the time given; failovers (the '
                  'module\'s term moved) and lapses of the cloud instance\'s lease (seen by the probe / logged by '
                  'the instance).', '',
                  report.markdown_table(['module', 's', 'RTT ms', 'loss', 'failovers', 'lapses', 'lapses logged'],
                                        [[x['module'], x['seconds'], x['rtt_ms'], x['loss'], x['failovers'],
                                          x['lapses'], x['lapses_logged']] for x in soaks])]
    check = summary.get('store_check') or {}
    lost = '–' if not check else (f'{check["missing_count"]} of {check["published_since_first"]} '
                                  f'({check["duplicates"]} stored twice)')
    lines += ['', f'Measurements lost (merged measurements the mission monitor saw between the store\'s first and '
                  f'newest, missing from the active store at the end): {lost}; move_base goals aborted: {aborted}.',
              '']
    title, reference = {('hot',): ('Hot migration downtime', 'thesis §4.2.5, method 2: hot-standby proxy'),
                        ('cold',): ('Cold migration and failover', 'thesis §4.2.5, method 1: stop and clone')}.get(
        tuple(sorted(set(args.modes))), ('Migration downtime and failover', 'thesis §4.2.5'))
    return results_page.write_page(out, title, reference, '\n'.join(lines), args.command,
                                   tables={'results.tsv': (COLUMNS, results),
                                           'failover.tsv': (FAILOVER_COLUMNS, failovers),
                                           **({'soak.tsv': (SOAK_COLUMNS, soaks)} if soaks else {})})


def experiment(modes: List[str]) -> str:
    """The results folder's name: migration_hot, migration_cold, or migration for a mixed run."""
    return f'migration_{modes[0]}' if len(set(modes)) == 1 else 'migration'


def main(argv: Optional[List[str]] = None) -> int:
    ap = cli.Parser('bench_migration.sh', __doc__)
    ap.add_argument('--runs', type=int, default=10)
    ap.add_argument('--rtts', default='0,50,100')
    ap.add_argument('--modules', default='move_base,local_mapcell_manager,global_goal_manager,mfg')
    ap.add_argument('--modes', default='cold,hot')
    ap.add_argument('--cutoff-trials', type=int, default=3)
    ap.add_argument('--standbys', default='cold,warm', help='what runs on the robot before a cut: cold (nothing), '
                                                          'warm (a standby)')
    ap.add_argument('--soak', type=float, default=0.0, help='s with every module on the cloud over a lossy link '
                                                          '(--soak-link; 0 = none)')
    ap.add_argument('--soak-link', default='100,0.05', help='RTT ms, loss fraction of the soak (both directions)')
    ap.add_argument('--settle', type=float, default=3.0, help='s after each migration before the next')
    ap.add_argument('--out', default=None, help="the page's folder (default docs/results/migration_<mode>, or "
                                                "migration for both modes)")
    ap.add_argument('--port', type=int, default=11411)
    ap.add_argument('--config-dir', default=os.path.join(report.WS, 'config'),
                    help='the configuration (e.g. a copy whose testbed.yaml turns the robot CPU cap off)')
    ap.add_argument('--slowdown', type=float, default=None,
                    help='cap the robot at 1/S CPU on a copy of --config-dir in bench_results/<experiment> (as '
                         'exp_campaign.sh --slowdown)')
    args = ap.parse_args(argv)
    args.command = cli.command(ap, argv)
    args.modules = [m for m in args.modules.split(',') if m]
    args.modes = [m for m in args.modes.split(',') if m]
    args.standbys = [m for m in args.standbys.split(',') if m]
    bad = [m for m in args.modes if m not in ('cold', 'hot')] + [m for m in args.modules if m not in OUTPUT_TOPIC] \
        + [m for m in args.standbys if m not in ('cold', 'warm')]
    if bad or not args.modes:
        ap.error(f'unknown mode, module or standby: {", ".join(bad)}')
    try:
        rtt_ms, loss = (float(x) for x in args.soak_link.split(','))
    except ValueError:
        ap.error(f'--soak-link must be "RTT_MS,LOSS", got {args.soak_link!r}')
    if rtt_ms < 0 or not 0.0 <= loss < 1.0 or args.soak < 0:
        ap.error(f'--soak-link needs RTT >= 0 and 0 <= loss < 1, --soak >= 0; got {args.soak_link}, {args.soak:g}')
    args.soak_link = (rtt_ms, loss)
    rtts = report.parse_rtts(ap.prog, args.rtts)
    args.scratch = results_page.scratch_dir(experiment(args.modes))
    args.out = os.path.abspath(args.out or results_page.results_dir(experiment(args.modes)))
    if args.slowdown is not None:
        from cnr_benchmarks.session import slowdown_config, testbed_running
        if args.slowdown < 1.0:
            print(f'{ap.prog}: --slowdown must be >= 1 (the robot gets 1/S CPU), got {args.slowdown:g}',
                  file=sys.stderr)
            return 2
        cli.require_root(ap.prog, "the testbed's network namespaces and TUN devices")
        if testbed_running(ap.prog):
            return 2
        args.config_dir = slowdown_config(args.scratch, args.slowdown, args.config_dir)
    cli.require_root(ap.prog, "the testbed's network namespaces and TUN devices")
    started = datetime.datetime.now().strftime('%Y-%m-%d %H:%M')
    bench = Bench(args)
    results = report.TsvLog(os.path.join(bench.out, 'results.tsv'), COLUMNS)
    failover = report.TsvLog(os.path.join(bench.out, 'failover.tsv'), FAILOVER_COLUMNS)
    soak = report.TsvLog(os.path.join(bench.out, 'soak.tsv'), SOAK_COLUMNS)
    summary: Dict = {}
    status = 0
    try:
        bench.start()
        for rtt in rtts:
            bench.set_rtt(rtt)
            report.progress(f'== RTT {rtt:g} ms')
            time.sleep(args.settle)
            bench.round_trips(results, rtt)
            if args.cutoff_trials > 0:
                bench.cutoffs(failover, rtt)
        if args.soak > 0:
            bench.soak(soak)
    except KeyboardInterrupt:
        report.progress('interrupted: writing what was measured')
    except MissionEnded as exc:
        report.progress(f'stopped: {exc}; writing what was measured')
        status = 1
    finally:
        summary = bench.stop()
        results.close()
        failover.close()
        soak.close()
    import csv
    res = list(csv.DictReader(open(results.path), delimiter='\t'))
    fo = list(csv.DictReader(open(failover.path), delimiter='\t'))
    soaks = list(csv.DictReader(open(soak.path), delimiter='\t'))
    aborted = 0
    if os.path.exists(bench.probe_file):
        aborted = sum(1 for r in read_probe(bench.probe_file) if r.topic == '/move_base/result' and r.instance == '4')
    report.progress(write_markdown(args.out, args, res, fo, summary, aborted, started, bench.probe_file, soaks))
    return status


if __name__ == '__main__':
    report.run_main(main)
