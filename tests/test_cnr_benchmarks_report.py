"""cnr_benchmarks.report's process handling without ROS: a long run started as a background job (SIGINT ignored
by the shell) stops on SIGINT, and its child (a testbed session) is stopped with SIGTERM, so it can clean up; a
resumable experiment runs only what is not finished."""
import os
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


def test_pending_runs_skip_the_finished_ones_and_finished_runs_load_them(tmp_path, capsys):
    from cnr_benchmarks import report

    def folder(key, i):
        return str(tmp_path / f'{key}-{i}')
    os.makedirs(folder('b', 1))
    open(os.path.join(folder('b', 1), 'summary.json'), 'w').close()
    todo = [(i, key, prefix) for i, key, _, prefix in report.pending_runs('x.sh', 2, ['a', 'b'], folder)]
    assert todo == [(1, 'a', '[x.sh] [1/4]'), (2, 'a', '[x.sh] [3/4]'), (2, 'b', '[x.sh] [4/4]')]
    assert 'b run 1: done before, kept' in capsys.readouterr().out
    loaded = report.finished_runs(2, ['a', 'b'], folder,
                                  lambda f, key, i: (key, i) if os.path.exists(os.path.join(f, 'summary.json')) else None)
    assert loaded == [('b', 1)]
