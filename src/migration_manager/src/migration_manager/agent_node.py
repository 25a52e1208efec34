"""``migration_agent``: starts and stops the managed module instances of one host (see the package README).

One per host, on that host's master. It only starts modules in its configured list, each as a *standby*: the
node that ``<launch_package> <launch_file> <module>:=true migration_role:=standby ...`` (normally cnr_mission
modules.launch) launches, resolved with roslaunch's loader (checked at start-up, again for each instance) and
started directly, without a launch parent per instance (:mod:`migration_manager.instance_launch`): its
parameters set on the master, then its process, in its own process group, output in
``<log_dir>/<host>-<module>-<n>.log``; promotion and freezing are the manager's business with the instance
itself. An instance that exits while it is wanted here (crashed, or superseded after an outage) is started
again as a standby after ``restart_delay``.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from typing import Dict, List, Optional

import rosgraph
import rospy

import cnr_params
from cnr_harness.process import Proc, stop_process
from cnr_msgs.msg import AgentHealth
from cnr_msgs.srv import AgentCommand, AgentCommandResponse
from cnr_params.config import EXIT_CONFIG
from cnr_params.ros import private_section
from cnr_runtime import init_node, quiet_at_shutdown
from migration_manager.codes import HEALTH
from migration_manager.core.config import from_section
from migration_manager.instance_launch import LaunchError, NodeLaunch, resolve


@dataclass
class Slot:
    module: str
    wanted: bool = False
    proc: Optional[Proc] = None
    started: int = 0
    exited_at: Optional[float] = None
    last_code: Optional[int] = None
    last_pid: int = 0
    stopping: Optional[Proc] = None       # an instance being stopped (SIGINT sent, not gone yet)


class Agent:
    def __init__(self) -> None:
        p = private_section('~')
        self.host = p.string('host')
        self.cfg = from_section(p.section('migration'))
        if self.host not in self.cfg.hosts:
            raise p.error('host', f'must be one of {", ".join(self.cfg.hosts)}, got {self.host!r}')
        launch_args = p.raw('launch_args')
        if not isinstance(launch_args, dict):
            raise p.error('launch_args', f'must be a mapping of modules.launch arguments, got {launch_args!r}')
        self.launch_args = {str(k): str(v) for k, v in launch_args.items()}
        self.launch = (p.string('launch_package'), p.string('launch_file'))
        self.master_uri = rosgraph.get_master_uri()
        for module in self.cfg.modules:          # a launch that cannot start a module is a configuration error now
            try:
                self._resolve(module)
            except LaunchError as exc:
                raise p.error('launch_file', str(exc)) from None
        self.log_dir = self.cfg.log_dir
        os.makedirs(self.log_dir, exist_ok=True)
        self.lock = threading.Lock()
        self.slots: Dict[str, Slot] = {m: Slot(m) for m in self.cfg.modules}
        base = f'/migration/agents/{self.host}'
        self.health_pub = rospy.Publisher(f'{base}/health', AgentHealth, queue_size=2, latch=True)
        rospy.Service(f'{base}/command', AgentCommand, self._on_command)
        rospy.loginfo(f'migration_agent on {self.host}: modules {", ".join(self.cfg.modules)}; logs in {self.log_dir}')

    def _args(self, module: str) -> List[str]:
        """The launch arguments of ``module``'s instances."""
        return [f'{module}:=true', 'migration_role:=standby', f'migration_host:={self.host}'] + \
            [f'{k}:={v}' for k, v in sorted(self.launch_args.items())]

    def _resolve(self, module: str) -> NodeLaunch:
        return resolve(*self.launch, module, self._args(module), self.master_uri)

    def _start(self, slot: Slot) -> None:
        slot.started += 1
        log = os.path.join(self.log_dir, f'{self.host}-{slot.module}-{slot.started}.log')
        try:
            launch = self._resolve(slot.module)     # the configuration as it is now, as roslaunch would read it
            launch.set_params(self.master_uri, self.cfg.control_call)
        except (OSError, LaunchError) as exc:       # tried again after restart_delay
            slot.proc, slot.exited_at, slot.last_code = None, time.monotonic(), None
            rospy.logwarn(f'{slot.module}: not started: {exc}')
            return
        slot.proc = Proc(launch.argv, log, env=launch.env)
        slot.last_pid = slot.proc.pid
        slot.exited_at = None
        rospy.loginfo(f'{slot.module}: started a standby (pid {slot.proc.pid}, log {log})')

    @quiet_at_shutdown
    def _on_command(self, req) -> AgentCommandResponse:
        slot = self.slots.get(req.module)
        if slot is None:
            return AgentCommandResponse(ok=False, message=f'{req.module!r} is not a module of this agent '
                                                          f'({", ".join(self.slots)})')
        if req.command == 'start':
            with self.lock:
                slot.wanted = True
                # an instance still being stopped does not count: a start right after a stop (a hot migration's
                # fresh standby on the old host) starts a new one; the old one goes on stopping
                if slot.proc is None or not slot.proc.alive() or slot.proc is slot.stopping:
                    self._start(slot)
                pid = slot.proc.pid if slot.proc is not None else 0
            self._health()
            return AgentCommandResponse(ok=True, message='running' if pid else 'starting (its parameters could '
                                        'not be set yet)', pid=pid)
        if req.command == 'stop':
            with self.lock:
                slot.wanted = False
                proc = slot.proc
                slot.stopping = proc
            threading.Thread(target=self._stop_quietly, args=(slot, proc), daemon=True).start()
            return AgentCommandResponse(ok=True, message='stopping', pid=proc.pid if proc else 0)
        return AgentCommandResponse(ok=False, message=f'unknown command {req.command!r} (start, stop)')

    def _stop_quietly(self, slot: Slot, proc: Optional[Proc]) -> None:
        if proc is None:
            return
        stop_process(proc.popen, timeout=self.cfg.stop_timeout)
        with self.lock:
            if slot.proc is proc:
                slot.proc = None
            if slot.stopping is proc:
                slot.stopping = None
        rospy.loginfo(f'{slot.module}: stopped')
        self._health()

    def _health(self) -> None:
        with self.lock:
            msg = AgentHealth(host=self.host, states=[])     # (a uint8[] field defaults to bytes)
            for s in self.slots.values():
                alive = s.proc is not None and s.proc.alive()
                msg.modules.append(s.module)
                msg.pids.append(s.last_pid)
                msg.restarts.append(max(0, s.started - 1))
                state = HEALTH['running' if alive else 'restarting' if s.wanted else
                               'exited' if s.last_code is not None else 'stopped']
                msg.states.append(state)
                msg.exit_codes.append(s.last_code if state == AgentHealth.EXITED else 0)
        msg.header.stamp = rospy.Time.from_sec(time.time())
        try:
            self.health_pub.publish(msg)
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise

    def spin(self) -> None:
        next_health = time.monotonic()
        while not rospy.core.is_shutdown_requested():
            now = time.monotonic()
            changed = False
            with self.lock:
                for s in self.slots.values():
                    if s.proc is not None and s.proc.poll() is not None and s.exited_at is None:
                        s.exited_at, s.last_code = now, s.proc.returncode
                        if s.last_code == EXIT_CONFIG and s.wanted:      # would only fail again: no restart loop
                            s.wanted = False
                            rospy.logerr(f'{s.module}: exited with status {EXIT_CONFIG} (bad configuration, see '
                                         f'{s.proc.log_path}): not started again')
                        else:
                            (rospy.logwarn if s.wanted else rospy.loginfo)(
                                f'{s.module}: exited with status {s.last_code}'
                                f'{"; a standby is started again" if s.wanted else ""}')
                        changed = True
                    if s.wanted and s.exited_at is not None and now - s.exited_at >= self.cfg.restart_delay:
                        self._start(s)
                        changed = True
            if changed or now >= next_health:
                next_health = now + self.cfg.status_period
                self._health()
            time.sleep(0.05)
        self.shutdown()

    def shutdown(self) -> None:
        with self.lock:
            procs = [s.proc for s in self.slots.values() if s.proc is not None]
            for s in self.slots.values():
                s.wanted, s.proc = False, None
        for proc in procs:
            stop_process(proc.popen, timeout=self.cfg.stop_timeout)


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('migration_agent')
    Agent().spin()
