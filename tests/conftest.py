"""Shared pytest fixtures: unit tests need nothing; integration tests get a real rosmaster on a free port.

``ros`` (session): one rosmaster (:class:`cnr_harness.RosMaster`) with ``/use_sim_time`` true and one
rospy test node for the whole session (``rospy.init_node`` works once per process). Test modules start
their nodes with ``ros.master.roslaunch(...)`` or ``ros.master.run([...])`` and stop them in their own
fixtures; process output goes to ``build/test_logs``.
"""
from __future__ import annotations

import inspect
import os
import re

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


# -- the fast tier ---------------------------------------------------------------------------------------------------
# A test is ``integration`` when it (or a fixture it uses) starts a master, a node, a launch, any other process, or
# needs the testbed (root); every other test is a ROS-free unit test of a core and runs in ``run_tests.sh --fast``.
_STARTS_SOMETHING = re.compile(
    r'\bros\b\s*[,)]|RosMaster|roslaunch|rosrun|launch_scripts|catkin_make|subprocess|Popen|spawn|Testbed|testbed'
    r'|netns|\bProc\b|require_root|geteuid|rospy\.init_node|ros\.master')


def _sources(item) -> list:
    sources = []
    func = getattr(item, 'function', None)
    if func is not None:
        sources.append(func)
    for name in item.fixturenames:
        for fixturedef in item._fixtureinfo.name2fixturedefs.get(name, ()):
            module = getattr(fixturedef.func, '__module__', '') or ''
            if not module.startswith('_pytest'):
                sources.append(fixturedef.func)
    # and the test module's own helpers they call, transitively
    module = getattr(item, 'module', None)
    helpers = {name: obj for name, obj in vars(module).items()
               if inspect.isfunction(obj) and obj.__module__ == module.__name__} if module else {}
    seen = set()
    while sources:
        obj = sources.pop()
        if obj in seen:
            continue
        seen.add(obj)
        try:
            text = inspect.getsource(obj)
        except (OSError, TypeError):
            continue
        for name, helper in helpers.items():
            if helper not in seen and re.search(rf'\b{name}\b', text):
                sources.append(helper)
    texts = []
    for obj in seen:
        try:
            texts.append(inspect.getsource(obj))
        except (OSError, TypeError):
            continue
    return texts


def pytest_collection_modifyitems(config, items) -> None:
    for item in items:
        if item.get_closest_marker('integration') is None and any(
                _STARTS_SOMETHING.search(text) for text in _sources(item)):
            item.add_marker(pytest.mark.integration)
    # the longest group first: with run_tests.sh's workers, the real-time missions on the default testbed (one
    # after the other, xdist group "default_testbed") start at once while the other worker takes everything else
    items.sort(key=lambda item: item.get_closest_marker('xdist_group') is None)
