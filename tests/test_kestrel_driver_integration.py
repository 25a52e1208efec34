"""kestrel_driver in device mode over a pseudo-terminal: lines become messages, garbage is skipped with a
warning, a vanished device is reconnected; bad scenario configuration exits with status 2."""
import os
import pty
import subprocess
import threading

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


def open_pty():
    master, slave = pty.openpty()
    import tty
    tty.setraw(slave)
    return master, os.ttyname(slave), slave


def load_defaults(ros, workspace, namespace):
    """config/kestrel_driver.yaml into the node's namespace, as mission.launch does (no defaults in code)."""
    subprocess.run(['rosparam', 'load', os.path.join(workspace, 'config', 'kestrel_driver.yaml'), namespace],
                   env=ros.master.env, check=True, capture_output=True, timeout=30)


def test_device_mode_over_a_pty(ros, workspace, tmp_path):
    from sensor_msgs.msg import Temperature
    m1, name1, s1 = open_pty()
    link = str(tmp_path / 'kestrel')
    os.symlink(name1, link)
    got, lock = [], threading.Lock()
    sub = rospy.Subscriber('/kt/temperature', Temperature, lambda msg: got.append(msg.temperature), queue_size=50)
    load_defaults(ros, workspace, '/kt/kestrel_driver')
    proc = ros.master.run(['rosrun', 'kestrel_driver', 'kestrel_driver', '__ns:=/kt', '_mode:=device',
                           f'_port:={link}', '_reconnect_interval:=0.3', '_lag_correction:=false'],
                          log_name='kestrel_device')
    try:
        def send(fd, text):
            os.write(fd, text.encode())
        wait_until(lambda: (send(m1, '23.4\r\n'), len(got) > 0)[1] or not proc.alive(), 60, 'a first temperature')
        assert proc.alive() and got[0] == pytest.approx(23.4)
        send(m1, 'garbage!!\n$KES,abc*00\n')
        send(m1, 'T,24.5\n')
        wait_until(lambda: any(abs(v - 24.5) < 1e-6 for v in got), 30, 'the value after garbage lines')
        # the device vanishes; a new one appears under the same name
        os.close(m1)
        os.close(s1)
        m2, name2, s2 = open_pty()
        os.remove(link)
        os.symlink(name2, link)
        wait_until(lambda: (send(m2, 'TEMP,25.5,C\n'), any(abs(v - 25.5) < 1e-6 for v in got))[1], 60,
                 'a value after reconnecting')
        assert proc.alive()
        out = proc.output()
        assert 'garbage' in out and ('lost the Kestrel' in out or 'cannot open' in out)
        os.close(m2)
        os.close(s2)
    finally:
        sub.unregister()
        proc.stop()


def test_missing_parameter_exits_2(ros):
    r = subprocess.run(['rosrun', 'kestrel_driver', 'kestrel_driver', '__name:=bare_kestrel'],
                       env=ros.master.env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    lines = [l for l in r.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and '/bare_kestrel: mode: missing' in lines[0], r.stderr


def test_bad_heat_source_exits_2(ros, workspace, tmp_path):
    load_defaults(ros, workspace, '/bad_kestrel')
    r = subprocess.run(['rosrun', 'kestrel_driver', 'kestrel_driver', '__name:=bad_kestrel',
                        '_temperature_field:={ambient: 22.0, sources: [{name: h, x: 1, y: 1, peak: 5, radius: -1, '
                        'start: 0.0, ramp: 0.0}]}'],
                       env=ros.master.env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    lines = [l for l in r.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and 'radius' in lines[0], r.stderr
