"""The ROS side of :class:`migration_manager.core.fence.CommandFence`: a fence that follows a module's leases on
``/migration/<module>/lease``. The simulator's ``~command_fence`` names :func:`move_base_fence` (cnr_sim calls
it with no argument and asks it, per velocity command, ``accept(connection header)`` and ``refusal(header)``).
"""
from __future__ import annotations

import threading
from typing import Mapping, Optional

import rospy

from cnr_msgs.msg import MigrationLease
from migration_manager.core.fence import CommandFence
from migration_manager.core.lease import Answer


class LeaseFence:
    """A :class:`CommandFence` for ``module`` fed by the grantor's lease answers and announcements."""

    def __init__(self, module: str) -> None:
        self.fence = CommandFence(module)
        self.lock = threading.Lock()
        rospy.Subscriber(f'/migration/{module}/lease', MigrationLease, self._on_lease, queue_size=20)

    def _on_lease(self, msg: MigrationLease) -> None:
        with self.lock:
            self.fence.on_lease(Answer(msg.module, msg.term, msg.holder, msg.nonce, msg.granted, msg.duration))

    def accept(self, header: Optional[Mapping[str, str]]) -> bool:
        with self.lock:
            return self.fence.accept(header)

    def refusal(self, header: Optional[Mapping[str, str]]) -> str:
        with self.lock:
            return self.fence.refusal(header)


def move_base_fence() -> LeaseFence:
    """The base's fence: velocity commands only from the move_base instance that holds the lease."""
    return LeaseFence('move_base')
