"""``kestrel_driver``: temperature measurements as sensor_msgs/Temperature (driver -> parser chain).

Sim mode samples the configured temperature field at the robot's true pose through the sensor's lag;
device mode reads a Kestrel on a serial port. See the package README for topics and parameters.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Temperature

import cnr_params
from cnr_params import Section
from cnr_params.ros import private_section
from cnr_runtime import init_node
from kestrel_driver.core.field import TemperatureField
from kestrel_driver.core.parser import ParseError, parse_line
from kestrel_driver.core.sensor import LagCorrector, LaggedSensor


@dataclass
class KestrelParams:
    mode: str
    rate: float
    frame_id: str
    variance: float
    time_constant: float
    noise_stddev: float
    lag_correction: bool
    correction_window: int
    pose_topic: str
    field: Optional[TemperatureField]
    port: str
    baud: int
    reconnect_interval: float
    seed: int


def read_params(p: Section) -> KestrelParams:
    """No defaults in code: they live in config/kestrel_driver.yaml (the field in the scenario file)."""
    mode = p.string('mode', choices=('sim', 'device'))
    return KestrelParams(
        mode=mode, rate=p.number('rate', positive=True), frame_id=p.string('frame_id'),
        variance=p.number('variance', nonnegative=True),
        time_constant=p.number('time_constant', nonnegative=True),
        noise_stddev=p.number('noise_stddev', nonnegative=True),
        lag_correction=p.boolean('lag_correction'),
        correction_window=p.integer('correction_window', minimum=2),
        pose_topic=p.string('pose_topic'),
        field=TemperatureField.from_section(p.section('temperature_field')) if mode == 'sim' else None,
        port=p.string('port'), baud=p.integer('baud', minimum=1),
        reconnect_interval=p.number('reconnect_interval', positive=True), seed=p.integer('seed'))


class KestrelNode:
    def __init__(self, params: KestrelParams) -> None:
        self.p = params
        self.pub = rospy.Publisher('temperature', Temperature, queue_size=10)
        self.raw_pub = rospy.Publisher('temperature_raw', Temperature, queue_size=10)
        self.corrector = LagCorrector(params.time_constant, params.correction_window) if params.lag_correction else None
        self.lock = threading.Lock()

    def _publish(self, value: float, stamp: rospy.Time, raw: bool = False) -> None:
        msg = Temperature()
        msg.header.stamp = stamp
        msg.header.frame_id = self.p.frame_id
        msg.temperature = value
        msg.variance = self.p.variance
        (self.raw_pub if raw else self.pub).publish(msg)

    def emit(self, reading: float, stamp: rospy.Time) -> None:
        """Publish a reading on temperature_raw, and on temperature (corrected when enabled)."""
        self._publish(reading, stamp, raw=True)
        value = self.corrector.update(reading, stamp.to_sec()) if self.corrector else reading
        self._publish(value, stamp)

    # -- sim mode ----------------------------------------------------------------------------
    def run_sim(self) -> None:
        sensor = LaggedSensor(self.p.time_constant)
        rng = np.random.default_rng(self.p.seed or None)
        air_pub = rospy.Publisher('~air_temperature', Temperature, queue_size=10)
        state = {'air': None, 'stamp': None}

        def on_pose(msg: Odometry) -> None:
            x, y = msg.pose.pose.position.x, msg.pose.pose.position.y
            t = msg.header.stamp.to_sec()
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(t)):
                rospy.logwarn_throttle(5.0, f'ignored a pose with non-finite values ({x}, {y})')
                return
            air = self.p.field.at(x, y, t)
            with self.lock:
                sensor.update(air, t)
                state['air'] = air

        rospy.Subscriber(self.p.pose_topic, Odometry, on_pose, queue_size=50)

        def on_timer(_event) -> None:
            with self.lock:
                if sensor.value is None:
                    return
                reading, air = sensor.value, state['air']
            stamp = rospy.Time.now()
            if stamp == state['stamp']:
                return      # a late timer catching up before the clock moved: one reading per instant
            state['stamp'] = stamp
            noisy = reading + (rng.normal(0.0, self.p.noise_stddev) if self.p.noise_stddev > 0 else 0.0)
            self.emit(noisy, stamp)
            m = Temperature()
            m.header.stamp, m.header.frame_id, m.temperature = stamp, self.p.frame_id, air
            air_pub.publish(m)

        rospy.Timer(rospy.Duration(1.0 / self.p.rate), on_timer)
        rospy.spin()

    # -- device mode -------------------------------------------------------------------------
    def run_device(self) -> None:
        import serial
        port = None
        garbage = 0
        while not rospy.is_shutdown():
            if port is None:
                try:
                    port = serial.Serial(self.p.port, self.p.baud, timeout=0.5)
                    rospy.loginfo(f'reading the Kestrel on {self.p.port} at {self.p.baud} baud')
                except (serial.SerialException, OSError) as exc:
                    rospy.logwarn_throttle(30.0, f'cannot open {self.p.port}: {exc}; retrying every '
                                                 f'{self.p.reconnect_interval:g} s')
                    time.sleep(self.p.reconnect_interval)
                    continue
            try:
                raw = port.readline()
            except (serial.SerialException, OSError) as exc:
                rospy.logwarn(f'lost the Kestrel on {self.p.port}: {exc}; reconnecting')
                try:
                    port.close()
                except Exception:
                    pass
                port = None
                time.sleep(self.p.reconnect_interval)
                continue
            if not raw:
                continue
            try:
                value = parse_line(raw.decode('ascii', errors='replace'))
            except ParseError as exc:
                garbage += 1
                rospy.logwarn_throttle(5.0, f'ignored a garbage line from {self.p.port} ({garbage} so far): {exc}')
                continue
            self.emit(value, rospy.Time.now())


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('kestrel_driver')
    params = read_params(private_section('~'))
    node = KestrelNode(params)
    if params.mode == 'sim':
        node.run_sim()
    else:
        node.run_device()
