"""Two bridged hosts on a testbed of a test module's own (root): the fixture code the bridge's testbed tests share.

    with two_hosts(workspace, name, log_dir, cloud_sim_time=True) as hosts:
        bridges = hosts.start_bridges(allow_topics=[...], allow_services=[...])
        hosts.robot.run([...]); hosts.tb.set('up', outage=True)
"""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import Iterator, List

from cnr_harness import Proc, wait_until


def log(proc: Proc) -> str:
    """The whole output of ``proc`` so far."""
    with open(proc.log_path, errors='replace') as f:
        return f.read()


@dataclass
class Hosts:
    tb: object          # cnr_testbed.api.Testbed
    robot: object       # cnr_testbed.rosside.RosSide
    cloud: object
    secret: str         # the bridges' shared secret file

    def start_bridges(self, **settings) -> List[Proc]:
        """A bridge on each host with ``settings`` (host file parameters), once they have heard each other."""
        from cnr_testbed.rosside import start_bridge
        procs = [start_bridge(self.robot, self.cloud, self.secret, **settings),
                 start_bridge(self.cloud, self.robot, self.secret, **settings)]
        wait_until(lambda: 'peer cloud is up' in log(procs[0]) and 'peer robot is up' in log(procs[1]), 60,
                   'the bridges to see each other')
        return procs

    def bridge_config(self, side: str, **settings) -> dict:
        """The parameters a bridge of :meth:`start_bridges` runs with on ``side``, config/bridge.yaml included."""
        import yaml
        from cnr_testbed.rosside import bridge_config
        here, peer = (self.robot, self.cloud) if side == 'robot' else (self.cloud, self.robot)
        ws = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        with open(os.path.join(ws, 'config', 'bridge.yaml')) as f:
            merged = yaml.safe_load(f)
        with open(bridge_config(here, peer, self.secret, **settings)) as f:
            merged.update(yaml.safe_load(f))
        return merged


@contextlib.contextmanager
def two_hosts(workspace: str, name: str, log_dir: str, cloud_sim_time: bool = False) -> Iterator[Hosts]:
    """A testbed named ``name`` (namespaces ``<name>-robot``, ``<name>-cloud``) with a master on each side and a
    shared secret; everything is stopped and removed on exit."""
    from cnr_testbed.api import Testbed
    from cnr_testbed.rosside import RosSide
    tb = Testbed(os.path.join(workspace, 'config', 'testbed.yaml'),
                 {'name': name, 'robot.namespace': f'{name}-robot', 'cloud.namespace': f'{name}-cloud'})
    tb.up()
    robot = RosSide(tb, 'robot', log_dir=log_dir)
    cloud = RosSide(tb, 'cloud', log_dir=log_dir)
    try:
        robot.start_master()
        cloud.start_master(use_sim_time=cloud_sim_time)
        secret = os.path.join(log_dir, 'secret')
        with open(secret, 'w') as f:
            f.write(f'{name}-test-secret\n')
        yield Hosts(tb, robot, cloud, secret)
    finally:
        cloud.stop()
        robot.stop()
        tb.down()
