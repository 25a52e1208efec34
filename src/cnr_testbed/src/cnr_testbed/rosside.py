"""ROS on one side of a running testbed: a rosmaster and nodes inside the side's network namespace.

Used by the benchmarks and the integration tests::

    with Testbed('config/testbed.yaml') as tb:
        robot, cloud = RosSide(tb, 'robot'), RosSide(tb, 'cloud')
        robot.start_master(); cloud.start_master()
        bridges = start_bridges(robot, cloud, secret_file, allow_topics=['/chatter'])
        ...
        cloud.stop(); robot.stop()

Every process is a :class:`cnr_harness.Proc` (own process group, output in a file, stopped with SIGINT,
then SIGTERM, then SIGKILL).
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
import xmlrpc.client
from typing import Dict, List, Optional, Sequence

import yaml

from cnr_harness import Proc, free_port, wait_until
from cnr_testbed import netns
from cnr_testbed.api import Testbed

BRIDGE_PORT = 11511


class RosSide:
    """One host of the testbed (``robot`` or ``cloud``) with its own environment and, optionally, its master.

    Args:
        testbed: a running :class:`Testbed`.
        side: ``robot`` or ``cloud``.
        master_side: whose master this side's nodes use (single-master set-ups point the cloud at the robot).
        port: master port (default: chosen at random, never 11311).
        log_dir: where process output goes.
    """

    def __init__(self, testbed: Testbed, side: str, master_side: Optional[str] = None, port: int = 0,
                 log_dir: Optional[str] = None, master_port: Optional[int] = None) -> None:
        self.testbed = testbed
        self.side = side
        self.namespace = testbed.namespace(side)
        self.address = testbed.robot_address if side == 'robot' else testbed.cloud_address
        master_side = master_side or side
        master_address = testbed.robot_address if master_side == 'robot' else testbed.cloud_address
        self.port = port or master_port or free_port()
        self.master_uri = f'http://{master_address}:{self.port}/'
        self.env = dict(os.environ, ROS_MASTER_URI=self.master_uri, ROS_IP=self.address,
                        ROS_HOME=os.environ.get('ROS_HOME', os.path.expanduser('~/.ros')))
        self.env.pop('ROS_HOSTNAME', None)
        self.log_dir = log_dir or tempfile.mkdtemp(prefix=f'cnr-{side}-')
        self.procs: List[Proc] = []
        self.master: Optional[Proc] = None

    def run(self, argv: Sequence[str], log_name: str = 'proc', env: Optional[Dict[str, str]] = None) -> Proc:
        """Start ``argv`` inside this side's namespace; stopped by :meth:`stop`."""
        proc = Proc(['ip', 'netns', 'exec', self.namespace, *argv],
                    os.path.join(self.log_dir, f'{log_name}-{time.monotonic_ns()}.log'), dict(self.env, **(env or {})))
        self.procs.append(proc)
        return proc

    def start_master(self, use_sim_time: bool = False, timeout: float = 20.0,
                     prefix: Sequence[str] = ()) -> None:
        """The side's rosmaster, one host's of several (:mod:`cnr_harness.rosmaster`: its calls to the other side's
        nodes never hold up its own); ``prefix`` wraps the command (e.g. :func:`cnr_testbed.cpucap.run_argv`'s)."""
        self.master = self.run([*prefix, sys.executable, '-m', 'cnr_harness.rosmaster', '--core', '-p',
                                str(self.port)], 'rosmaster')
        wait_until(self.master_up, timeout, f'the rosmaster of {self.side}', self.master)
        self.call('setParam', '/use_sim_time', use_sim_time)

    def call(self, method: str, *args):
        """One Master API call, made from inside this side's namespace."""
        with netns.inside(self.namespace):
            code, msg, value = getattr(xmlrpc.client.ServerProxy(self.master_uri), method)('/cnr_testbed', *args)
        if code != 1:
            raise RuntimeError(f'{method}{args}: {msg}')
        return value

    def master_up(self) -> bool:
        try:
            self.call('getPid')
            return True
        except (OSError, RuntimeError):
            return False

    def stop_proc(self, proc: Proc) -> None:
        proc.stop()
        if proc in self.procs:
            self.procs.remove(proc)

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()
        self.procs.clear()
        self.master = None


def bridge_config(side: RosSide, peer: RosSide, secret_file: str, **settings) -> str:
    """Write a bridge YAML for ``side`` peering with ``peer``; returns its path."""
    cfg = dict(name=side.side, listen=f'{side.address}:{BRIDGE_PORT}',
               peers=[dict(name=peer.side, address=f'{peer.address}:{BRIDGE_PORT}')],
               secret_file=secret_file, **settings)
    path = os.path.join(side.log_dir, f'bridge_{side.side}.yaml')
    with open(path, 'w') as f:
        yaml.safe_dump(cfg, f)
    return path


def start_bridge(side: RosSide, peer: RosSide, secret_file: str, **settings) -> Proc:
    """The multimaster bridge of ``side`` (rosrun, parameters from a YAML file written for it)."""
    path = bridge_config(side, peer, secret_file, **settings)
    return side.run(['roslaunch', 'multimaster_bridge', 'bridge.launch', f'config:={path}',
                     f'secret_file:={secret_file}', 'output:=screen'], f'bridge_{side.side}')
