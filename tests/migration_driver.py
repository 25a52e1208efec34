"""Test side of a managed module instance on one master: the test plays the migration manager with the real
lease core (migration_manager.core.lease.Grantor) and the real protocol (renewals answered on
/migration/<module>/lease, the instance's control service), so a single node can be promoted, frozen and cut
off (renewals no longer answered) without a second host.

    driver = LeaseDriver('mfg', 'robot')            # after the node was started with ~migration params
    driver.wait_standby(30)
    driver.promote(state=None)                      # or a dict: handed over as the module's state
    driver.wait_active(10)
    state = driver.freeze()                         # the final state (a dict)

One grantor for instances on both hosts (a migration on one master: stop the first instance before the second,
of the same node name, starts):

    driver = LeaseDriver('move_base', hosts=('robot', 'cloud'))
    driver.promote(host='robot'); ...; state = driver.freeze(host='robot')
    driver.promote(state, host='cloud')
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, Optional, Sequence

import rospy

from cnr_harness import wait_until
from cnr_msgs.msg import InstanceStatus, MigrationLease, MigrationRenew
from cnr_msgs.srv import InstanceControl
from migration_manager.core import state as codec
from migration_manager.core.lease import Grantor, instance_id


def managed_params(workspace: str, host: str = 'robot') -> Dict[str, Any]:
    """The ``~migration`` parameters of a managed instance (config/migration.yaml + role and host)."""
    import os
    from cnr_params import load_yaml
    return dict(load_yaml(os.path.join(workspace, 'config', 'migration.yaml')), role='standby', host=host)


class LeaseDriver:
    def __init__(self, module: str, host: str = '', duration: float = 0.6, margin: float = 0.15,
                 hosts: Sequence[str] = ()) -> None:
        self.hosts = tuple(hosts) or (host,)
        self.module, self.host = module, self.hosts[0]          # host: the default of every call
        self.instance = instance_id(module, self.host)
        self.grantor = Grantor(module, duration, margin)
        self.lock = threading.Lock()
        self.answering = True
        self.statuses: Dict[str, Optional[InstanceStatus]] = {h: None for h in self.hosts}
        self.pub = rospy.Publisher(f'/migration/{module}/lease', MigrationLease, queue_size=50)
        self.subs = [rospy.Subscriber(f'/migration/{module}/renew', MigrationRenew, self._on_renew, queue_size=50)]
        self.controls = {}
        for h in self.hosts:
            self.subs.append(rospy.Subscriber(f'/migration/{module}/{h}/status', InstanceStatus,
                                              lambda m, h=h: self.statuses.__setitem__(h, m), queue_size=10))
            self.controls[h] = rospy.ServiceProxy(f'/migration/{module}/{h}/control', InstanceControl)
        self.control = self.controls[self.host]

    @property
    def status(self) -> Optional[InstanceStatus]:
        return self.statuses[self.host]

    def _on_renew(self, msg: MigrationRenew) -> None:
        with self.lock:
            if not self.answering:
                return
            a = self.grantor.request(msg.instance, msg.term, msg.nonce, time.monotonic())
        self.pub.publish(MigrationLease(module=a.module, term=a.term, holder=a.holder, nonce=a.nonce,
                                        granted=a.granted, duration=a.duration))

    def wait_role(self, role: str, timeout: float, host: str = '') -> InstanceStatus:
        host = host or self.host

        def seen():
            st = self.statuses[host]
            return st if st is not None and st.role == role else None
        return wait_until(seen, timeout, f'{instance_id(self.module, host)} {role}')

    def wait_standby(self, timeout: float, host: str = '') -> InstanceStatus:
        rospy.wait_for_service(f'/migration/{self.module}/{host or self.host}/control', timeout)
        return self.wait_role('standby', timeout, host)

    def promote(self, state: Optional[Dict[str, Any]] = None, host: str = '') -> int:
        host = host or self.host
        with self.lock:
            term = self.grantor.promote(instance_id(self.module, host), time.monotonic())
        data = codec.encode(self.module, state) if state is not None else b''
        res = self.controls[host]('promote', term, data)
        assert res.ok, res.message
        return term

    def wait_active(self, timeout: float, host: str = '') -> InstanceStatus:
        return self.wait_role('active', timeout, host)

    def freeze(self, host: str = '') -> Dict[str, Any]:
        host = host or self.host
        res = self.controls[host]('freeze', self.grantor.term, b'')
        assert res.ok, res.message
        with self.lock:
            self.grantor.release(instance_id(self.module, host), self.grantor.term)
        return codec.decode(self.module, res.state)

    def state(self, host: str = '') -> Dict[str, Any]:
        res = self.controls[host or self.host]('state', 0, b'')
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
