"""cnr_benchmarks.report's process handling without ROS: a long run started as a background job (SIGINT ignored
by the shell) stops on SIGINT, and its child (a testbed session) is stopped with SIGTERM, so it can clean up."""
import signal
import subprocess
import sys

from cnr_harness.process import wait_until

CHILD = '''
import pathlib, signal, sys, time
def cleaned(*_):
    pathlib.Path(sys.argv[2]).write_text('cleaned up')
    sys.exit(0)
signal.signal(signal.SIGTERM, cleaned)
pathlib.Path(sys.argv[1]).write_text('ready')
time.sleep(60)
'''

PARENT = '''
import sys
from cnr_benchmarks import report
report.stop_on_signals()
try:
    report.call([sys.executable, '-c', sys.argv[1], sys.argv[2], sys.argv[3]])
except KeyboardInterrupt:
    print('interrupted')
    sys.exit(3)
'''


def _background_job(argv):
    """Started as a non-interactive shell starts ``cmd &``: SIGINT ignored."""
    return subprocess.Popen(argv, stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))


def _interrupted(tmp_path, sig):
    """A background run whose child is running, sent ``sig``: (exit status, output, the child's clean-up file)."""
    ready, cleaned = tmp_path / 'ready', tmp_path / 'cleaned'
    parent = _background_job([sys.executable, '-c', PARENT, CHILD, str(ready), str(cleaned)])
    try:
        wait_until(ready.exists, 20, 'the child to start')
        parent.send_signal(sig)
        out, _ = parent.communicate(timeout=20)
    finally:
        parent.kill()
    return parent.returncode, out, cleaned


def test_sigint_to_a_background_run_stops_it_and_its_child_cleans_up(tmp_path):
    status, out, cleaned = _interrupted(tmp_path, signal.SIGINT)
    assert status == 3 and 'interrupted' in out
    assert cleaned.read_text() == 'cleaned up'


def test_sigterm_stops_it_too_and_call_returns_the_exit_code(tmp_path):
    status, out, cleaned = _interrupted(tmp_path, signal.SIGTERM)
    assert status == 3 and cleaned.exists()
    from cnr_benchmarks import report
    assert report.call([sys.executable, '-c', 'import sys; sys.exit(7)']) == 7
