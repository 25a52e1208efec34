"""What the simulator is given from outside (ROS-free): the fence on its velocity commands and the reader of a
cgroup's CPU time. cnr_sim depends on no implementation of either: its parameters name them as plugins
(``package.module:name``, loaded when the node starts), so the configuration chooses them.

- ``~command_fence`` (config/simulator.yaml): a factory called with no argument, returning a
  :class:`CommandGate` ('' = none: every command is obeyed);
- ``~battery/cpu_usage`` (config/battery.yaml): a factory called with ``~battery/cpu_cgroup``, returning a
  :class:`CpuUsage` (used only when a cgroup is named).
"""
from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping, Optional, Protocol


class CommandGate(Protocol):
    """Decides, per velocity command, whether its publisher may move the base."""

    def accept(self, header: Optional[Mapping[str, str]]) -> bool:
        """True if a command from a publisher with this connection header may move the base."""

    def refusal(self, header: Optional[Mapping[str, str]]) -> str:
        """Why such a command was refused (for the log)."""


class CpuUsage(Protocol):
    """The CPU seconds a group of processes used so far."""

    problem: str            # why the last read failed ('' if it did not)

    def read(self) -> Optional[float]:
        """Seconds of CPU used so far, or None when they cannot be read (see ``problem``)."""


def check_spec(spec: str) -> str:
    """A plugin name's problem ('' if it has the form ``package.module:name``)."""
    module, sep, name = spec.partition(':')
    if not sep or not module or not name.isidentifier() or not all(p.isidentifier() for p in module.split('.')):
        return f'must be package.module:name, got {spec!r}'
    return ''


def load(spec: str) -> Callable[..., Any]:
    """The object a plugin name names; ValueError saying why it cannot be loaded."""
    problem = check_spec(spec)
    if problem:
        raise ValueError(problem)
    module, _, name = spec.partition(':')
    try:
        found = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f'cannot load {spec}: {exc}') from None
    if not callable(found):
        raise ValueError(f'{spec} is not callable')
    return found
