"""The process harness: waits, process groups, output files, a rosmaster on a free port."""
import os
import sys
import time

import pytest

from cnr_harness import Proc, RosMaster, WaitTimeout, free_port, master_answers, wait_until


def test_wait_until_returns_the_value_and_names_what_it_waited_for():
    t0 = time.monotonic()
    assert wait_until(lambda: time.monotonic() > t0 + 0.1 and 'done', 5, 'the clock') == 'done'
    with pytest.raises(WaitTimeout, match='waiting for nothing at all'):
        wait_until(lambda: False, 0.2, 'nothing at all')


def test_wait_until_fails_at_once_when_the_watched_process_exits(tmp_path):
    proc = Proc([sys.executable, '-c', 'raise SystemExit(3)'], str(tmp_path / 'exit.log'))
    t0 = time.monotonic()
    with pytest.raises(WaitTimeout, match='exited with 3'):
        wait_until(lambda: False, 30, 'something', proc)
    assert time.monotonic() - t0 < 10


def test_output_reaches_the_file_unbuffered_and_stop_ends_the_group(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONUNBUFFERED'}
    code = ('import subprocess, sys, time; '
            'c = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"]); '
            'print("child", c.pid); time.sleep(600)')
    proc = Proc([sys.executable, '-c', code], str(tmp_path / 'group.log'), env)
    line = wait_until(lambda: [ln for ln in proc.output().splitlines() if ln.startswith('child ')], 20,
                      'the first line in the log file')
    child = int(line[0].split()[1])
    assert proc.stop(timeout=5) is not None
    wait_until(lambda: not os.path.exists(f'/proc/{child}') or open(f'/proc/{child}/stat').read().split()[2] == 'Z',
               10, 'the grandchild to end with its group')


def test_stop_escalates_when_sigint_is_ignored(tmp_path):
    code = 'import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); print("ready"); time.sleep(600)'
    proc = Proc([sys.executable, '-c', code], str(tmp_path / 'stubborn.log'))
    wait_until(lambda: 'ready' in proc.output(), 20, 'the stubborn process')
    assert proc.stop(timeout=0.5) == -15          # SIGTERM after the SIGINT timeout


def test_free_port_is_never_the_ros_default():
    assert all(free_port() != 11311 for _ in range(20))


def test_a_master_on_a_free_port_answers_and_is_gone_after_stop(tmp_path):
    master = RosMaster(log_dir=str(tmp_path), use_sim_time=True)
    try:
        assert master.port != 11311 and master_answers(master.uri)
        assert master.call('getParam', '/use_sim_time') is True
        echo = master.run([sys.executable, '-c', 'import os; print(os.environ["ROS_MASTER_URI"])'], 'echo')
        wait_until(lambda: master.uri in echo.output(), 20, 'the child to see ROS_MASTER_URI')
    finally:
        master.stop()
    assert not master.proc.alive() and not master_answers(master.uri)
