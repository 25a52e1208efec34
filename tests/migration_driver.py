"""Test side of a managed module instance on one master: the test plays the migration manager with the real
lease core (migration_manager.core.lease.Grantor) and the real protocol (renewals answered on
/migration/<module>/lease, the instance's control service), so a single node can be promoted, frozen and cut
off (renewals no longer answered) without a second host.

    driver = LeaseDriver('mfg', 'robot')            # after the node was started with ~migration params
    driver.wait_standby(30)
    driver.promote(state=None)                      # or a dict: handed over as the module's state
    driver.wait_active(10)
    state = driver.freeze()                         # the final state (a dict)
"""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, Optional

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
    def __init__(self, module: str, host: str, duration: float = 0.6, margin: float = 0.15) -> None:
        self.module, self.host = module, host
        self.instance = instance_id(module, host)
        self.grantor = Grantor(module, duration, margin)
        self.lock = threading.Lock()
        self.answering = True
        self.status: Optional[InstanceStatus] = None
        self.pub = rospy.Publisher(f'/migration/{module}/lease', MigrationLease, queue_size=50)
        self.subs = [rospy.Subscriber(f'/migration/{module}/renew', MigrationRenew, self._on_renew, queue_size=50),
                     rospy.Subscriber(f'/migration/{module}/{host}/status', InstanceStatus,
                                      lambda m: setattr(self, 'status', m), queue_size=10)]
        self.control = rospy.ServiceProxy(f'/migration/{module}/{host}/control', InstanceControl)

    def _on_renew(self, msg: MigrationRenew) -> None:
        with self.lock:
            if not self.answering:
                return
            a = self.grantor.request(msg.instance, msg.term, msg.nonce, time.monotonic())
        self.pub.publish(MigrationLease(module=a.module, term=a.term, holder=a.holder, nonce=a.nonce,
                                        granted=a.granted, duration=a.duration))

    def wait_role(self, role: str, timeout: float) -> InstanceStatus:
        return wait_until(lambda: self.status if self.status is not None and self.status.role == role else None,
                          timeout, f'{self.instance} {role}')

    def wait_standby(self, timeout: float) -> InstanceStatus:
        rospy.wait_for_service(f'/migration/{self.module}/{self.host}/control', timeout)
        return self.wait_role('standby', timeout)

    def promote(self, state: Optional[Dict[str, Any]] = None) -> int:
        with self.lock:
            term = self.grantor.promote(self.instance, time.monotonic())
        data = codec.encode(self.module, state) if state is not None else b''
        res = self.control('promote', term, data)
        assert res.ok, res.message
        return term

    def wait_active(self, timeout: float) -> InstanceStatus:
        return self.wait_role('active', timeout)

    def freeze(self) -> Dict[str, Any]:
        res = self.control('freeze', self.grantor.term, b'')
        assert res.ok, res.message
        with self.lock:
            self.grantor.release(self.instance, self.grantor.term)
        return codec.decode(self.module, res.state)

    def state(self) -> Dict[str, Any]:
        res = self.control('state', 0, b'')
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
