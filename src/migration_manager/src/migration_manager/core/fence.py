"""An actuator's fence (ROS-free): commands only from the instance that holds the lease (the simulator's base
obeys move_base's through :mod:`migration_manager.fence`).

migration_manager moves move_base between the robot and the cloud; its leases make sure at most one instance
commands at any time, and the fence here makes sure the base obeys only that one even if an old instance's
commands are still on their way (queued in a link, a frozen process not stopped yet). A managed instance marks
its publishers with the connection header :data:`migration_manager.core.lease.INSTANCE_HEADER` (``module@host``);
the actuator hears the grantor's lease answers and announcements (``/migration/<module>/lease``) and keeps the
newest term's holder (:class:`migration_manager.core.lease.TermFilter`). A command is accepted when

- it carries no instance header (an unmanaged move_base, teleop, a test), or the header names an instance of
  another module (not this fence's to judge), or
- no lease of the module was heard yet (nothing is managed), or
- its instance is the current holder.

Everything else (an old or frozen instance, any instance while the module has no holder) is dropped.
"""
from __future__ import annotations

from typing import Mapping, Optional

from migration_manager.core.lease import INSTANCE_HEADER, Answer, TermFilter


class CommandFence:
    """Decides, per command, whether its publisher may command the base.

    Args:
        module: the managed module whose instances command the base (move_base).
    """

    def __init__(self, module: str) -> None:
        self.module = module
        self.filter = TermFilter()
        self.dropped = 0                  # commands refused so far

    def on_lease(self, answer: Answer) -> None:
        """A lease answer or announcement heard on ``/migration/<module>/lease``."""
        if answer.module == self.module:
            self.filter.on_answer(answer)

    @staticmethod
    def instance_of(header: Optional[Mapping[str, str]]) -> Optional[str]:
        """The instance named by a connection header, None if there is none."""
        return (header or {}).get(INSTANCE_HEADER) or None

    def accept(self, header: Optional[Mapping[str, str]]) -> bool:
        """True if a command from a publisher with this connection header may move the base."""
        instance = self.instance_of(header)
        if instance is None or instance.rpartition('@')[0] != self.module:
            return True
        ok = self.filter.accept(self.module, instance)
        if not ok:
            self.dropped += 1
        return ok

    def refusal(self, header: Optional[Mapping[str, str]]) -> str:
        """Why a command from a publisher with this connection header was refused (for the log)."""
        return (f'ignored velocity commands from {self.instance_of(header)}: {self.module} is held by '
                f'{self.holder() or "no instance"} ({self.dropped} dropped so far)')

    def holder(self) -> str:
        """The current holder ('' none; 'unmanaged' if no lease was heard)."""
        known = self.filter.current.get(self.module)
        return 'unmanaged' if known is None else known.holder
