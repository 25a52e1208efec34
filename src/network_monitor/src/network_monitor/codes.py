"""The uint8 codes of the network monitor's enumerated message field (cnr_msgs constants) and the words its
cores speak: word -> code; ``*_WORD`` is its inverse. Used at the ROS boundary only. The decider's messages have
theirs in :mod:`network_monitor.decider_codes` (its words come with the k-NN: this module stays light for the
monitor node).
"""
from __future__ import annotations

from typing import Dict

from cnr_msgs.msg import NetworkProfile

#: NetworkProfile.a_bw_method, and TaskDecision.profile_method (the same values)
A_BW_METHOD: Dict[str, int] = {'none': NetworkProfile.NONE, 'probe': NetworkProfile.PROBE,
                               'passive': NetworkProfile.PASSIVE}
A_BW_METHOD_WORD: Dict[int, str] = {c: w for w, c in A_BW_METHOD.items()}
