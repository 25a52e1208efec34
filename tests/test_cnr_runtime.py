"""cnr_runtime.quiet_at_shutdown: a ROSException ends a callback quietly only once the shutdown has begun.

Runs in a child interpreter, because a rospy shutdown cannot be undone in this one (no master needed)."""
import subprocess
import sys

import pytest

pytest.importorskip('rospy')

SCRIPT = r'''
import rospy, rospy.core
from cnr_runtime import quiet_at_shutdown

@quiet_at_shutdown
def publish_onto_closed_topic():
    raise rospy.ROSException("publish() to a closed topic")

@quiet_at_shutdown
def broken():
    raise ValueError("a real bug")

try:
    publish_onto_closed_topic()
    print("before: swallowed")
except rospy.ROSException:
    print("before: raised")
rospy.core.signal_shutdown("test")
print("after:", publish_onto_closed_topic())
try:
    broken()
except ValueError:
    print("bug: raised")
'''


def test_quiet_only_after_the_shutdown_began():
    out = subprocess.run([sys.executable, '-c', SCRIPT], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split('\n')[:3] == ['before: raised', 'after: None', 'bug: raised'], out.stdout
