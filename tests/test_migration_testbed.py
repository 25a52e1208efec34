"""migration_manager on the testbed (root): two masters in the robot and cloud namespaces, their bridges, a
migration agent on each host, the manager on the robot, and a consumer (migration_probe) on the robot that
calls the global goal manager 20 times a second and records which instance answered.

- cold migration robot -> cloud -> robot is make-before-break: the consumer's gap is the hand-over only, and
  the old instance's output stops before the new one's starts (never two active);
- a hot migration to a warm standby;
- exactly one active under a partition: cut the link while the module is active on the cloud: the cloud
  instance closes its outputs, the robot's is promoted; after the link returns there is still exactly one;
  with a warm standby on the robot, it is active once the cloud's short lease ran out;
- rollback: a target that crashes at start leaves the module where it was, answering throughout;
- a migration ordered while the link is down is rolled back: the module is not stranded on the unreachable side;
- the robot's active instance killed: its agent's restart is promoted (recovery on the same host).
The figures (downtime) are the benchmark's business (launch_scripts/bench_migration.sh); bounds here are loose.
"""
import csv
import os
import subprocess
import time

import pytest
import yaml

from cnr_harness import WaitTimeout, wait_until

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason='needs root (network namespaces, TUN devices)')

NAME = f'mig{os.getpid() % 10000}'
MODULE = 'global_goal_manager'


class Bed:
    def __init__(self, workspace, logs):
        from cnr_testbed.api import Testbed
        self.ws, self.logs = workspace, logs
        self.tb = Testbed(os.path.join(workspace, 'config', 'testbed.yaml'),
                          {'name': NAME, 'robot.namespace': f'{NAME}-robot', 'cloud.namespace': f'{NAME}-cloud'})
        self.tb.up()
        self.robot = self.cloud = None
        try:
            self._start(workspace, logs)
        except BaseException:
            self.close()                     # nothing left behind when the set-up fails
            raise

    def _start(self, workspace, logs):
        from cnr_bringup.placement import load_catalog
        from cnr_params import load_yaml
        from cnr_testbed.rosside import RosSide, start_bridge
        self.robot = RosSide(self.tb, 'robot', log_dir=str(logs))
        self.cloud = RosSide(self.tb, 'cloud', log_dir=str(logs))
        self.sides = {'robot': self.robot, 'cloud': self.cloud}
        for side in self.sides.values():
            side.start_master()
        secret = logs / 'secret'
        secret.write_text('migration-test-secret\n')
        cfg = os.path.join(workspace, 'config')
        placement = load_catalog(os.path.join(cfg, 'placements.yaml')).placement('all_robot').managed_by([MODULE])
        for side, peer in ((self.robot, self.cloud), (self.cloud, self.robot)):
            host = load_yaml(os.path.join(cfg, f'bridge_{side.side}.yaml'))
            start_bridge(side, peer, str(secret), allow_topics=placement.allow('topics'),
                         allow_services=placement.allow('services'), deny_topics=host['deny_topics'],
                         deny_services=host['deny_services'])
        # the scenario each host's instances load: a copy the rollback test can break
        self.scenario = logs / 'scenario.yaml'
        self.scenario.write_text(open(os.path.join(cfg, 'scenarios', 'corridor.yaml')).read())
        migration = dict(load_yaml(os.path.join(cfg, 'migration.yaml')), modules=[MODULE], hot_standby=[])
        migration['agent'] = dict(migration['agent'], log_dir=str(logs / 'instances'))
        map_file = os.path.join(workspace, 'maps', 'corridor.yaml')
        for name, side in self.sides.items():
            side.call('setParam', '/migration_agent', dict(
                host=name, launch_package='cnr_mission', launch_file='modules.launch', migration=migration,
                launch_args=dict(config_dir=cfg, scenario_file=str(self.scenario), map=map_file,
                                 store=str(logs / f'store_{name}.tsv'))))
            side.run(['rosrun', 'migration_manager', 'migration_agent'], f'agent_{name}')
        # cell states for the goal manager: an (unmanaged) local_mapcell_manager on the robot
        self.robot.run(['rosrun', 'cnr_bringup', 'cnr_launch', 'cnr_mission', 'modules.launch',
                        'local_mapcell_manager:=true', f'config_dir:={cfg}', f'scenario_file:={self.scenario}',
                        f'map:={map_file}', f'store:={logs / "store_lmm.tsv"}'], 'lmm')
        self.robot.call('setParam', '/migration_manager', dict(migration=migration, placement={MODULE: 'robot'},
                                                                start_modules=True))
        self.manager = self.robot.run(['rosrun', 'migration_manager', 'migration_manager'], 'manager')
        self.probe_file = logs / 'probe.tsv'
        self.robot.call('setParam', '/migration_probe', dict(topics=['/global_goal'], next_goal_rate=20.0,
                                                              status_modules=[MODULE], hosts=['robot', 'cloud'],
                                                              out=str(self.probe_file)))
        self.robot.run(['rosrun', 'migration_manager', 'migration_probe'], 'probe')
        wait_until(lambda: self.placement().get(MODULE, ('',))[0] == 'robot', 120, f'{MODULE} active on the robot')
        wait_until(lambda: self.answers(time.time() - 1.0), 60, 'the probe to get answers')

    def rosrun(self, side, *argv, timeout=60):
        return subprocess.run(['ip', 'netns', 'exec', self.sides[side].namespace, *argv], env=self.sides[side].env,
                              capture_output=True, text=True, timeout=timeout)

    def placement(self):
        out = self.rosrun('robot', 'rosrun', 'migration_manager', 'migrate', '--placement', '--timeout', '5')
        rows = [l.split() for l in out.stdout.splitlines() if l.strip()]
        return {r[0]: (r[1] if r[1] != '-' else '', int(r[3]), '(migrating)' in r) for r in rows}

    def migrate(self, target, mode=''):
        argv = ['rosrun', 'migration_manager', 'migrate', MODULE, target] + (['--mode', mode] if mode else [])
        return self.rosrun('robot', *argv, timeout=120)

    def status(self, side):
        """The instance's latched status on its host's master (its role in words); None when no instance
        publishes one."""
        from migration_manager.codes import ROLE_WORD
        try:
            out = self.rosrun(side, 'rostopic', 'echo', '-n', '1', f'/migration/{MODULE}/{side}/status', timeout=8)
        except subprocess.TimeoutExpired:
            return None
        status = yaml.safe_load(out.stdout.split('---')[0]) if out.returncode == 0 else None
        return dict(status, role=ROLE_WORD.get(status.get('role'))) if status else None

    def rows(self):
        with open(self.probe_file) as f:
            return list(csv.DictReader(f, delimiter='\t'))

    def diagnosis(self) -> str:
        """What a failed wait for answers shows: the probe's last calls, the robot master's provider of next_goal,
        the bridge's and the manager's last lines."""
        calls = [f"{r['time']} ok={r['ok']} {r['instance']}" for r in self.rows() if r['topic'] == 'next_goal'][-8:]
        info = self.rosrun('robot', 'rosservice', 'info', '/global_goal_manager/next_goal', timeout=15)
        tails = []
        for name in ('bridge_robot', 'manager', 'agent_robot'):
            for path in sorted(self.logs.glob(f'{name}-*.log')):
                lines = [l for l in path.read_text(errors='replace').splitlines() if l.startswith('[')]
                tails.append(f'--- {path.name}\n' + '\n'.join(l[:200] for l in lines[-8:]))
        return '\n'.join(['probe calls:', *calls, 'robot master:', info.stdout + info.stderr, *tails])

    def answers(self, since):
        return [float(r['time']) for r in self.rows() if r['topic'] == 'next_goal' and r['ok'] == '1'
                and float(r['time']) >= since]

    def activations(self, since):
        """When the robot's instance became active (the probe's ``active`` rows: the status's stamp)."""
        return [float(r['time']) for r in self.rows() if r['topic'] == 'active'
                and r['instance'] == f'{MODULE}@robot' and float(r['time']) >= since]

    def outputs(self, since):
        return [(float(r['time']), r['instance']) for r in self.rows()
                if r['topic'] == '/global_goal' and float(r['time']) >= since]

    def close(self):
        for side in (self.cloud, self.robot):
            if side is not None:
                side.stop()
        self.tb.down()


@pytest.fixture(scope='module')
def bed(workspace):
    import pathlib
    import shutil
    logs = pathlib.Path(workspace, 'build', 'test_logs', 'migration_testbed')      # kept for a post-mortem
    shutil.rmtree(logs, ignore_errors=True)
    logs.mkdir(parents=True)
    b = None
    try:
        b = Bed(workspace, logs)
        yield b
    finally:
        if b is not None:
            b.close()


def largest_gap(times):
    return max((b - a for a, b in zip(times, times[1:])), default=float('inf'))


def switch_is_clean(outputs, old, new):
    """The old instance's outputs all come before the new one's first (never both)."""
    first_new = next(i for i, (_, inst) in enumerate(outputs) if inst == new)
    return all(inst == new for _, inst in outputs[first_new:]) and \
        all(inst == old for _, inst in outputs[:first_new])


def test_cold_round_trip_is_make_before_break(bed):
    for source, target in (('robot', 'cloud'), ('cloud', 'robot')):
        t0 = time.time()
        res = bed.migrate(target, 'cold')
        assert res.returncode == 0, res.stdout + res.stderr
        assert ': done' in res.stdout and 'hand-over' in res.stdout, res.stdout
        wait_until(lambda: len(bed.answers(time.time() - 1.0)) >= 5, 30, f'answers from {target}')
        t1 = time.time()
        wait_until(lambda: any(inst == f'{MODULE}@{target}' for _, inst in bed.outputs(t0)), 20,
                   f'the probe to receive the {target} instance\'s output')
        outputs = bed.outputs(t0)
        assert switch_is_clean(outputs, f'{MODULE}@{source}', f'{MODULE}@{target}'), outputs
        gap = largest_gap(bed.answers(t0 - 0.5))
        print(f'cold {source}->{target}: {res.stdout.strip()}; consumer gap {1000 * gap:.0f} ms')
        assert gap < 2.0                         # the target for cold migration
        assert bed.placement()[MODULE][0] == target
        # the source's instance is gone (cold): its agent stopped it
        wait_until(lambda: bed.status(source) is None or bed.status(source)['role'] in ('frozen', 'superseded'), 30,
                   f'the {source} instance to be stopped')
        assert t1 - t0 < 60


def test_hot_migration_to_a_warm_standby(bed):
    res = bed.rosrun('robot', 'rosservice', 'call', '/migration/agents/cloud/command', 'start', MODULE)
    assert res.returncode == 0 and 'ok: True' in res.stdout, res.stdout + res.stderr
    wait_until(lambda: (bed.status('cloud') or {}).get('role') == 'standby', 120, 'a warm standby on the cloud')
    t0 = time.time()
    res = bed.migrate('cloud', 'hot')
    assert res.returncode == 0, res.stdout + res.stderr
    wait_until(lambda: len(bed.answers(time.time() - 1.0)) >= 5, 30, 'answers from the cloud')
    gap = largest_gap(bed.answers(t0 - 0.5))
    print(f'hot robot->cloud: {res.stdout.strip()}; consumer gap {1000 * gap:.0f} ms')
    wait_until(lambda: any(inst == f'{MODULE}@cloud' for _, inst in bed.outputs(t0)), 20,
               'the probe to receive the cloud instance\'s output')
    assert switch_is_clean(bed.outputs(t0), f'{MODULE}@robot', f'{MODULE}@cloud')
    assert gap < 2.0


def test_a_start_right_after_a_stop_starts_a_new_standby(bed):
    """The agent on the robot (the module is active on the cloud): a standby started, then stopped and at once
    started again (what a hot migration does on its old host) is a new process that becomes a standby, not the
    old one still being stopped."""
    import re

    def command(verb):
        res = bed.rosrun('robot', 'rosservice', 'call', '/migration/agents/robot/command', verb, MODULE)
        assert res.returncode == 0 and 'ok: True' in res.stdout, res.stdout + res.stderr
        return int(re.search(r'pid: (\d+)', res.stdout).group(1))
    first = command('start')
    wait_until(lambda: (bed.status('robot') or {}).get('role') == 'standby', 120, 'a standby on the robot')
    # stop, then start at once, from one client (as the manager does): no rosservice start-up in between
    script = ('import rospy, sys\n'
              'from cnr_msgs.srv import AgentCommand\n'
              'call = rospy.ServiceProxy("/migration/agents/robot/command", AgentCommand)\n'
              f'stop, start = call("stop", "{MODULE}"), call("start", "{MODULE}")\n'
              'print(stop.ok, stop.pid, start.ok, start.pid)\n')
    res = bed.rosrun('robot', '/usr/bin/python3', '-c', script)
    assert res.returncode == 0, res.stdout + res.stderr
    stop_ok, stopped, start_ok, second = res.stdout.split()
    assert stop_ok == start_ok == 'True' and int(stopped) == first
    assert int(second) != first, 'the start was taken by the instance being stopped'
    wait_until(lambda: (bed.status('robot') or {}).get('role') == 'standby', 120, 'the new standby on the robot')
    command('stop')


def test_exactly_one_active_under_a_partition(bed):
    if bed.placement()[MODULE][0] != 'cloud':
        assert bed.migrate('cloud', 'cold').returncode == 0
    term_cloud = bed.placement()[MODULE][1]
    bed.tb.set('both', outage=True)
    try:
        t_cut = time.time()
        wait_until(lambda: bed.placement()[MODULE][0] == 'robot', 60, 'the failover to the robot')
        wait_until(lambda: len(bed.answers(time.time() - 1.0)) >= 5, 30, 'answers from the robot during the outage')
        print(f'failover: answers again {bed.answers(t_cut)[0] - t_cut:.2f} s after the cut')
        # the cut-off cloud instance has closed its outputs (its lease ran out): it is not active
        wait_until(lambda: (bed.status('cloud') or {}).get('role') != 'active', 10,
                   'the cut-off cloud instance to close its outputs')
    finally:
        bed.tb.set('both', outage=False)
    # back: the old cloud instance learns of the newer term and steps down; one active instance, on the robot
    wait_until(lambda: (bed.status('cloud') or {}).get('role') in (None, 'standby', 'superseded', 'frozen'), 60,
               'the cloud instance to step down')
    p = bed.placement()[MODULE]
    assert p[0] == 'robot' and p[1] > term_cloud
    assert (bed.status('robot') or {}).get('role') == 'active'
    assert (bed.status('cloud') or {}).get('role') != 'active'


def test_a_warm_standby_on_the_robot_replaces_a_cut_off_cloud_instance_once_its_short_lease_ran_out(bed):
    """The module on the cloud, a warm standby on the robot (config/migration.yaml hot_standby keeps one): after
    a cut the robot's standby is active once the cloud instance's lease (lease.duration + margin) ran out, not
    after a clone's start; the cut-off instance closed its outputs before and steps down once the link is back.
    The bound here is loose (a loaded machine); the figures are bench_migration.sh's (docs/results/failover)."""
    from migration_manager.core.config import from_section
    from cnr_params import Section, load_yaml
    lease = from_section(Section(load_yaml(os.path.join(bed.ws, 'config', 'migration.yaml')), 'migration.yaml')).lease
    if bed.placement()[MODULE][0] != 'cloud':
        assert bed.migrate('cloud', 'cold').returncode == 0
    res = bed.rosrun('robot', 'rosservice', 'call', '/migration/agents/robot/command', 'start', MODULE)
    assert res.returncode == 0 and 'ok: True' in res.stdout, res.stdout + res.stderr
    wait_until(lambda: (bed.status('robot') or {}).get('role') == 'standby', 120, 'a warm standby on the robot')
    wait_until(lambda: len(bed.answers(time.time() - 1.0)) >= 5, 30, 'answers from the cloud')
    bed.tb.set('both', outage=True)
    try:
        t_cut = time.time()
        wait_until(lambda: bed.placement()[MODULE][0] == 'robot', 60, 'the failover to the robot')
        wait_until(lambda: bed.activations(t_cut), 10, 'the robot instance\'s activation in the probe\'s rows')
        took = bed.activations(t_cut)[0] - t_cut
        wait_until(lambda: bed.answers(t_cut + took), 30, 'answers from the robot')
        print(f'warm failover: the robot instance active {took:.2f} s after the cut, answers again '
              f'{bed.answers(t_cut + took)[0] - t_cut:.2f} s after it')
        assert took < lease.duration + lease.margin + 0.75     # a clone would first start (seconds)
    finally:
        bed.tb.set('both', outage=False)
    wait_until(lambda: (bed.status('cloud') or {}).get('role') in (None, 'standby', 'superseded', 'frozen'), 60,
               'the cloud instance to step down')
    assert bed.placement()[MODULE][0] == 'robot' and (bed.status('robot') or {}).get('role') == 'active'


def test_the_robot_s_active_instance_killed_is_replaced_by_its_restart(bed):
    """The robot's own active instance dies (SIGKILL): its agent starts it again as a standby, and the manager
    promotes that standby once the dead one's lease ran out (before, nothing promoted it: the module had no
    active instance until the next migration order)."""
    import signal
    from cnr_msgs.msg import AgentHealth
    if bed.placement()[MODULE][0] != 'robot':
        assert bed.migrate('robot', 'cold').returncode == 0
    term = bed.placement()[MODULE][1]
    out = bed.rosrun('robot', 'rostopic', 'echo', '-n', '1', '/migration/agents/robot/health', timeout=15)
    health = yaml.safe_load(out.stdout.split('---')[0])
    pid = health['pids'][health['modules'].index(MODULE)]
    assert pid > 0 and health['states'][health['modules'].index(MODULE)] == AgentHealth.RUNNING, health
    t_kill = time.time()
    os.kill(pid, signal.SIGKILL)
    wait_until(lambda: bed.placement()[MODULE][1] > term and bed.placement()[MODULE][0] == 'robot', 90,
               'a new term on the robot')
    try:
        wait_until(lambda: bed.answers(t_kill + 0.5), 30, 'answers from the restarted instance')
    except WaitTimeout as exc:
        raise AssertionError(f'{exc}\n{bed.diagnosis()}') from None
    print(f'answers again {bed.answers(t_kill + 0.5)[0] - t_kill:.1f} s after the kill')
    assert (bed.status('robot') or {}).get('role') == 'active'
    assert (bed.status('cloud') or {}).get('role') != 'active'


def test_a_target_that_crashes_at_start_is_rolled_back(bed):
    if bed.placement()[MODULE][0] != 'robot':
        assert bed.migrate('robot', 'cold').returncode == 0
    bed.rosrun('robot', 'rosservice', 'call', '/migration/agents/cloud/command', 'stop', MODULE)
    wait_until(lambda: (bed.status('cloud') or {}).get('role') != 'standby', 30, 'no standby on the cloud')
    good = bed.scenario.read_text()
    data = yaml.safe_load(good)
    data['global_goal_manager']['policy'] = 'no_such_policy'         # the new instance exits at start (status 2)
    bed.scenario.write_text(yaml.safe_dump(data))
    try:
        t0 = time.time()
        res = bed.migrate('cloud', 'cold')
        assert res.returncode == 1 and 'rolled_back' in res.stdout, res.stdout + res.stderr
        assert time.time() - t0 < 25                 # noticed at the crash, not at the start timeout
    finally:
        bed.scenario.write_text(good)
    assert bed.placement()[MODULE][0] == 'robot'
    gap = largest_gap(bed.answers(t0))
    assert gap < 1.0, f'{gap}\n{bed.diagnosis()}'                           # the robot's instance answered throughout


def test_a_migration_ordered_while_the_link_is_down_does_not_strand_the_module(bed):
    """The cloud is unreachable when the migration is ordered: the manager (on the robot) rolls it back, the
    robot's instance answers throughout and stays the only active one; once the link is back the same order
    succeeds, and the robot can take the module back."""
    if bed.placement()[MODULE][0] != 'robot':
        assert bed.migrate('robot', 'cold').returncode == 0
    term = bed.placement()[MODULE][1]
    bed.tb.set('both', outage=True)
    try:
        t0 = time.time()
        res = bed.migrate('cloud', 'cold')
        took = time.time() - t0
        print(f'ordered during the outage: {res.stdout.strip()} ({took:.1f} s)')
        assert res.returncode == 1 and ('rolled_back' in res.stdout or 'failed' in res.stdout), \
            res.stdout + res.stderr
        p = bed.placement()[MODULE]
        assert p[0] == 'robot' and not p[2], p
        assert (bed.status('robot') or {}).get('role') == 'active'
        gap = largest_gap(bed.answers(t0))
        assert gap < 1.0, f'{gap}\n{bed.diagnosis()}'                       # the robot's instance answered throughout
    finally:
        bed.tb.set('both', outage=False)
    # the cloud instance a start request may have left behind never became active
    assert (bed.status('cloud') or {}).get('role') != 'active'
    wait_until(lambda: bed.migrate('cloud', 'cold').returncode == 0, 120, 'the migration to succeed after the outage',
               interval=5.0)
    assert bed.placement()[MODULE][0] == 'cloud' and bed.placement()[MODULE][1] > term
    assert bed.migrate('robot', 'cold').returncode == 0
    assert bed.placement()[MODULE][0] == 'robot'
