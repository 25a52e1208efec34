"""Shared pytest fixtures: unit tests need nothing; integration tests get a real rosmaster on a free port.

``ros`` (session): one rosmaster (:class:`cnr_harness.RosMaster`) with ``/use_sim_time`` true and one
rospy test node for the whole session (``rospy.init_node`` works once per process). Test modules start
their nodes with ``ros.master.roslaunch(...)`` or ``ros.master.run([...])`` and stop them in their own
fixtures; process output goes to ``build/test_logs``.
"""
from __future__ import annotations

import os

import pytest

from cnr_harness import RosMaster

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class RosSession:
    def __init__(self, master: RosMaster) -> None:
        self.master = master


@pytest.fixture(scope='session')
def ros():
    """A rosmaster on a free port plus an initialised rospy node in this process."""
    master = RosMaster(log_dir=os.path.join(WS, 'build', 'test_logs'), use_sim_time=True, caller='/pytest')
    os.environ['ROS_MASTER_URI'] = master.uri
    os.environ['ROS_IP'] = '127.0.0.1'
    import rospy
    rospy.init_node('pytest', anonymous=True, disable_signals=True)
    try:
        yield RosSession(master)
    finally:
        rospy.signal_shutdown('pytest session over')
        master.stop()


@pytest.fixture(scope='session')
def workspace() -> str:
    return WS
