"""The simulator's two battery packs on a real rosmaster: the base's on battery_state and the robot computer's on
laptop_charge (config/battery.yaml), at the same rate, each with its own capacity and consumers."""
import threading

import pytest

from cnr_harness import wait_until

rospy = pytest.importorskip('rospy')


def test_both_packs_are_published_at_the_same_rate(ros, workspace):
    from sensor_msgs.msg import BatteryState
    got = {'battery_state': [], 'laptop_charge': []}
    lock = threading.Lock()

    def keep(msg, topic):
        with lock:
            got[topic].append(msg)

    subs = [rospy.Subscriber(t, BatteryState, keep, t, queue_size=20) for t in got]
    proc = ros.master.roslaunch('cnr_sim', 'simulator.launch', 'real_time_factor:=4.0', 'x:=0.5', 'y:=0.0')
    try:
        wait_until(lambda: all(len(m) >= 6 for m in got.values()) or not proc.alive(), 120,
                   'six readings of each battery pack')
        assert proc.alive(), proc.output()[-2000:]
    finally:
        for s in subs:
            s.unregister()
        proc.stop()
    with lock:
        by_stamp = {t: {m.header.stamp.to_sec(): m for m in msgs} for t, msgs in got.items()}
    # stamped together, at ~battery/publish_rate (1 Hz of sim time)
    stamps = sorted(set(by_stamp['battery_state']) & set(by_stamp['laptop_charge']))
    assert len(stamps) >= 5, by_stamp
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert sum(1 for g in gaps if g == pytest.approx(1.0, abs=0.021)) >= 3, stamps    # (a reading may be missed)
    assert all(g >= 0.99 for g in gaps), stamps
    base = [by_stamp['battery_state'][t] for t in stamps]
    computer = [by_stamp['laptop_charge'][t] for t in stamps]
    assert (base[0].location, computer[0].location) == ('kobuki', 'netbook')
    assert (base[0].design_capacity, computer[0].design_capacity) == pytest.approx((2.2, 5.2))
    assert 13.2 <= base[-1].voltage <= 16.5 and 9.0 <= computer[-1].voltage <= 12.6
    # each pack drains by its own consumers: the base's idle draw, the laptop's idle draw (+ CPU and radio)
    assert base[-1].percentage < base[0].percentage and computer[-1].percentage < computer[0].percentage
    assert 'motors=' in base[-1].serial_number and 'cpu=' not in base[-1].serial_number
    assert 'cpu=' in computer[-1].serial_number and 'motors=' not in computer[-1].serial_number
    assert base[-1].current < 0 and computer[-1].current < 0
