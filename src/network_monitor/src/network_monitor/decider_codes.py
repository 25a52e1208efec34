"""The uint8 codes of the migration_decider's enumerated message fields (cnr_msgs constants) and the words the
cores, the training sets and the reports speak: one mapping per field, word -> code; ``*_WORD`` is its inverse.
Used at the ROS boundary only (the decider node and the tools that call it). TaskDecision.profile_method takes
:data:`network_monitor.codes.A_BW_METHOD`.
"""
from __future__ import annotations

from typing import Dict

from cnr_msgs.msg import TaskDecision
from cnr_msgs.srv import DecideRequest, EvaluateTaskRequest
from network_monitor.core.advisor import FORCED, REDECISION
from network_monitor.core.decision import COLD_START, EXPLORE, KNN, NO_PROFILE
from network_monitor.core.evaluation import ABORTED, COMPLETED, OFFLOAD, ONLOAD, TIMED_OUT

#: TaskDecision.event
EVENT: Dict[str, int] = {'decided': TaskDecision.DECIDED, 'redecided': TaskDecision.REDECIDED,
                         'evaluated': TaskDecision.EVALUATED}
EVENT_WORD: Dict[int, str] = {c: w for w, c in EVENT.items()}

#: TaskDecision.decision, .policy and .label ('': none, a label before the task is evaluated)
PLACEMENT: Dict[str, int] = {'': TaskDecision.NO_PLACEMENT, OFFLOAD: TaskDecision.OFFLOAD,
                             ONLOAD: TaskDecision.ONLOAD}
PLACEMENT_WORD: Dict[int, str] = {c: w for w, c in PLACEMENT.items()}

#: TaskDecision.reason
REASON: Dict[str, int] = {KNN: TaskDecision.KNN, COLD_START: TaskDecision.COLD_START,
                          EXPLORE: TaskDecision.EXPLORE, NO_PROFILE: TaskDecision.NO_PROFILE,
                          FORCED: TaskDecision.FORCED, REDECISION: TaskDecision.REDECISION}
REASON_WORD: Dict[int, str] = {c: w for w, c in REASON.items()}

#: TaskDecision.mission_status and EvaluateTask's mission_status (the same values; '': not evaluated yet)
MISSION_STATUS: Dict[str, int] = {'': TaskDecision.NO_STATUS, COMPLETED: TaskDecision.COMPLETED,
                                  ABORTED: TaskDecision.ABORTED, TIMED_OUT: TaskDecision.TIMED_OUT}
MISSION_STATUS_WORD: Dict[int, str] = {c: w for w, c in MISSION_STATUS.items()}

#: Decide's force ('': decide)
FORCE: Dict[str, int] = {'': DecideRequest.DECIDE, OFFLOAD: DecideRequest.OFFLOAD, ONLOAD: DecideRequest.ONLOAD}
FORCE_WORD: Dict[int, str] = {c: w for w, c in FORCE.items()}

assert (EvaluateTaskRequest.COMPLETED, EvaluateTaskRequest.ABORTED, EvaluateTaskRequest.TIMED_OUT) == \
    (TaskDecision.COMPLETED, TaskDecision.ABORTED, TaskDecision.TIMED_OUT), 'EvaluateTask.srv and TaskDecision.msg'
