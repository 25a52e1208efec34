"""Test side of a managed module instance on one master: the test plays the migration manager with the real
lease core (migration_manager.core.lease.Grantor) and the real protocol (renewals answered on
/migration/<module>/lease, the instance's control service), so a single node can be promoted, frozen and cut
off (renewals no longer answered) without a second host.

    driver = LeaseDriver('mfg', 'robot')            # after the node was started with ~migration params
    driver.wait_standby(30)
    driver.promote(state=None)                      # or a dict: handed over as the module's state
    driver.wait_active(10)
    state = driver.freeze()                         # the final state (a dict)

One driver (one grantor, as with the real manager) can control a module's instances on several hosts, e.g. a
hand-over between two instances on one master (started under different node names):

    driver = LeaseDriver('local_mapcell_manager', hosts=('robot', 'cloud'))
    driver.promote(host='robot'); ...; state = driver.freeze(host='robot'); driver.promote(state, host='cloud')

Without ``host=`` a method addresses the first host.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

import rospy

from cnr_harness import wait_until
from cnr_msgs.msg import InstanceStatus, MigrationLease, MigrationRenew
from cnr_msgs.srv import InstanceControl
from migration_manager.codes import ROLE
from migration_manager.core import state as codec
from migration_manager.core.lease import Grantor, instance_id


def managed_params(workspace: str, host: str = 'robot') -> Dict[str, Any]:
    """The ``~migration`` parameters of a managed instance (config/migration.yaml + role and host)."""
    import os
    from cnr_params import load_yaml
    return dict(load_yaml(os.path.join(workspace, 'config', 'migration.yaml')), role='standby', host=host)


def instance_names(module: str) -> Dict[str, str]:
    """The node name of a module's instance on each host in the one-master tests (robot: the module's, cloud:
    ``<module>_b``)."""
    return {'robot': module, 'cloud': f'{module}_b'}


def instance_starter(master, driver: 'LeaseDriver', module: str, params_of: Callable[[str], Dict[str, Any]],
                     log_prefix: str) -> Tuple[Callable[[str], Any], Dict[str, Any]]:
    """``start(host)``: one managed instance of ``module`` on ``master`` (named by :func:`instance_names`) with
    ``params_of(host)``, waited for as a standby; and the processes started, by host."""
    procs: Dict[str, Any] = {}
    names = instance_names(module)

    def start(host: str):
        name = names[host]
        master.call('setParam', f'/{name}', params_of(host))
        procs[host] = master.run(['rosrun', module, module, f'__name:={name}'], f'{log_prefix}_{host}')
        driver.wait_standby(30, host=host)
        return procs[host]
    return start, procs


class LeaseDriver:
    def __init__(self, module: str, host: str = '', duration: float = 0.6, margin: float = 0.15,
                 hosts: Sequence[str] = ()) -> None:
        self.hosts = tuple(hosts) or (host,)
        assert all(self.hosts) and (not host or host == self.hosts[0]), 'a host, or hosts (the first is the default)'
        self.module, self.host = module, self.hosts[0]
        self.instance = instance_id(module, self.host)
        self.grantor = Grantor(module, duration, margin)
        self.lock = threading.Lock()
        self.answering = True
        self.last_promotion_active = False
        self.statuses: Dict[str, Optional[InstanceStatus]] = {h: None for h in self.hosts}
        self.pub = rospy.Publisher(f'/migration/{module}/lease', MigrationLease, queue_size=50)
        self.subs = [rospy.Subscriber(f'/migration/{module}/renew', MigrationRenew, self._on_renew, queue_size=50)]
        self.subs += [rospy.Subscriber(f'/migration/{module}/{h}/status', InstanceStatus,
                                       lambda m, h=h: self.statuses.__setitem__(h, m), queue_size=10)
                      for h in self.hosts]
        self.controls = {h: rospy.ServiceProxy(f'/migration/{module}/{h}/control', InstanceControl)
                         for h in self.hosts}
        self.control = self.controls[self.host]

    @property
    def status(self) -> Optional[InstanceStatus]:
        return self.statuses[self.host]

    def _on_renew(self, msg: MigrationRenew) -> None:
        with self.lock:
            if not self.answering:
                return
            if msg.term == 0:                 # a standby's request: kept for a pre-granted promotion
                self.grantor.standby_request(msg.instance, msg.nonce, time.monotonic())
                return
            a = self.grantor.request(msg.instance, msg.term, msg.nonce, time.monotonic())
        self.pub.publish(MigrationLease(module=a.module, term=a.term, holder=a.holder, nonce=a.nonce,
                                        granted=a.granted, duration=a.duration))

    def wait_role(self, role: str, timeout: float, host: str = '') -> InstanceStatus:
        host = host or self.host

        def reached():
            s = self.statuses[host]
            return s if s is not None and s.role == ROLE[role] else None
        return wait_until(reached, timeout, f'{instance_id(self.module, host)} {role}')

    def wait_standby(self, timeout: float, host: str = '') -> InstanceStatus:
        rospy.wait_for_service(f'/migration/{self.module}/{host or self.host}/control', timeout)
        return self.wait_role('standby', timeout, host)

    def promote(self, state: Optional[Dict[str, Any]] = None, host: str = '', pregrant: bool = False,
                data: Optional[bytes] = None, base_instance: str = '') -> int:
        """Promote (with ``pregrant``: the order carries the lease for the instance's newest standby request, as
        the manager does; the instance must then answer that it is active). ``data``: the state as sent (e.g. a
        patch to a replica of ``base_instance``) instead of ``state``."""
        host = host or self.host
        with self.lock:
            term = self.grantor.promote(instance_id(self.module, host), time.monotonic())
            nonce, duration = (self.grantor.pregrant(instance_id(self.module, host), time.monotonic())
                               if pregrant else (0, 0.0))
        if data is None:
            data = codec.encode(self.module, state) if state is not None else b''
        res = self.controls[host](command='promote', term=term, state=data, nonce=nonce, duration=duration,
                                  base_instance=base_instance)
        assert res.ok, res.message
        assert res.active or not nonce, f'pre-granted promotion to term {term} but not active'
        self.last_promotion_active = res.active
        return term

    def wait_active(self, timeout: float, host: str = '') -> InstanceStatus:
        return self.wait_role('active', timeout, host)

    def freeze(self, host: str = '') -> Dict[str, Any]:
        return codec.decode(self.module, self.freeze_data(host))

    def freeze_data(self, host: str = '', base_seq: int = 0) -> bytes:
        """Freeze; the final state as sent: a patch to replica ``base_seq`` if the instance still has it."""
        host = host or self.host
        res = self.controls[host](command='freeze', term=self.grantor.term, base_seq=base_seq)
        assert res.ok, res.message
        with self.lock:
            self.grantor.release(instance_id(self.module, host), self.grantor.term)
        return bytes(res.state)

    def state(self, host: str = '') -> Dict[str, Any]:
        res = self.controls[host or self.host](command='state')
        assert res.ok, res.message
        return codec.decode(self.module, res.state)

    def cut_off(self) -> None:
        """Renewals are no longer answered (the instance's link to the manager is gone)."""
        with self.lock:
            self.answering = False

    def close(self) -> None:
        for s in self.subs:
            s.unregister()
        self.pub.unregister()
