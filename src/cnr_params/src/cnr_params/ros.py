"""Parameter-server side of :mod:`cnr_params`: read a node's private namespace as a :class:`Section`."""
from __future__ import annotations

import rospy

from cnr_params.config import Section


def private_section(namespace: str = '~') -> Section:
    """All parameters under ``namespace`` as one :class:`Section` (one getParam call).

    Errors name the resolved namespace, e.g. ``/simulator: laser.max_range: must be > 0``.
    """
    resolved = rospy.resolve_name(namespace)
    data = rospy.get_param(namespace, {})
    return Section(data if isinstance(data, dict) else {}, resolved.rstrip('/') or '/')
