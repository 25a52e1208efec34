"""The uint8 codes of migration_manager's enumerated message fields (cnr_msgs constants) and the words the code,
the logs and the command line speak: one mapping per field, word -> code; ``*_WORD`` is its inverse. Used at the
ROS boundary only (the cores keep their words: :class:`migration_manager.core.plan.Step`, ``'cold'``/``'hot'``).
"""
from __future__ import annotations

from typing import Dict

from cnr_msgs.msg import AgentHealth, InstanceStatus, MigrationEvent
from cnr_msgs.srv import MigrateRequest, MigrateResponse
from migration_manager.core.plan import Step

#: InstanceStatus.role
ROLE: Dict[str, int] = {'standby': InstanceStatus.STANDBY, 'active': InstanceStatus.ACTIVE,
                        'promoted': InstanceStatus.PROMOTED, 'frozen': InstanceStatus.FROZEN,
                        'superseded': InstanceStatus.SUPERSEDED, 'dormant': InstanceStatus.DORMANT}
ROLE_WORD: Dict[int, str] = {c: w for w, c in ROLE.items()}

#: AgentHealth.states (an exited process's status is in exit_codes)
HEALTH: Dict[str, int] = {'running': AgentHealth.RUNNING, 'stopped': AgentHealth.STOPPED,
                          'exited': AgentHealth.EXITED, 'restarting': AgentHealth.RESTARTING}
HEALTH_WORD: Dict[int, str] = {c: w for w, c in HEALTH.items()}

#: MigrationEvent.mode
EVENT_MODE: Dict[str, int] = {'cold': MigrationEvent.COLD, 'hot': MigrationEvent.HOT}
EVENT_MODE_WORD: Dict[int, str] = {c: w for w, c in EVENT_MODE.items()}

#: MigrationEvent.step
STEP: Dict[Step, int] = {Step.STARTING: MigrationEvent.STARTING, Step.FREEZING: MigrationEvent.FREEZING,
                         Step.WAITING_LEASE: MigrationEvent.WAITING_LEASE, Step.PROMOTING: MigrationEvent.PROMOTING,
                         Step.ROLLING_BACK: MigrationEvent.ROLLING_BACK, Step.DONE: MigrationEvent.DONE,
                         Step.ROLLED_BACK: MigrationEvent.ROLLED_BACK, Step.FAILED: MigrationEvent.FAILED}
STEP_WORD: Dict[int, str] = {c: s.value for s, c in STEP.items()}

#: Migrate request's target (a host of config/migration.yaml hosts)
TARGET: Dict[str, int] = {'robot': MigrateRequest.ROBOT, 'cloud': MigrateRequest.CLOUD}
TARGET_WORD: Dict[int, str] = {c: w for w, c in TARGET.items()}

#: Migrate request's mode ('': the module's default)
MODE: Dict[str, int] = {'': MigrateRequest.DEFAULT, 'cold': MigrateRequest.COLD, 'hot': MigrateRequest.HOT}
MODE_WORD: Dict[int, str] = {c: w for w, c in MODE.items()}

#: Migrate response's outcome: a finished migration's last step, or refused
OUTCOME: Dict[str, int] = {'done': MigrateResponse.DONE, 'rolled_back': MigrateResponse.ROLLED_BACK,
                           'failed': MigrateResponse.FAILED, 'refused': MigrateResponse.REFUSED}
OUTCOME_WORD: Dict[int, str] = {c: w for w, c in OUTCOME.items()}


def health_word(state: int, exit_code: int) -> str:
    """One AgentHealth entry in words: running, stopped, restarting, or ``exited (status)``."""
    word = HEALTH_WORD.get(state, f'state {state}')
    return f'{word} ({exit_code})' if state == AgentHealth.EXITED else word
