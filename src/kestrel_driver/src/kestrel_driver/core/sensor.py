"""The Kestrel's slow thermometer and a correction of its lag.

ROS-free. The sensing element follows Newton's law of cooling, dT/dt = (T_air - T) / tau, which makes a
robot that drives past a heater see the peak late, lower and smeared along its path (the skewed, larger
hotspots the thesis observed). :class:`LagCorrector` inverts the model, T_air ~ T + tau dT/dt, with the
derivative from a least-squares line over a short window of readings (the thesis's future work).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Deque, Optional, Tuple

import numpy as np


class LaggedSensor:
    """First-order lag with exact discretisation for piecewise-constant input.

    Args:
        time_constant: tau [s] (0 = no lag).
        initial: reading before the first update [degC] (None: the first air temperature).
    """

    def __init__(self, time_constant: float, initial: Optional[float] = None) -> None:
        self.tau = time_constant
        self.value = initial
        self.t: Optional[float] = None

    def update(self, air: float, t: float) -> float:
        """Advance to time t [s] with air temperature ``air`` [degC]; returns the reading."""
        if self.value is None or self.t is None:
            self.value = air if self.value is None else self.value
            self.t = t
            return self.value
        dt = max(t - self.t, 0.0)
        self.t = t
        if self.tau <= 0:
            self.value = air
        else:
            self.value = air + (self.value - air) * math.exp(-dt / self.tau)
        return self.value


class LagCorrector:
    """Estimates the air temperature from lagged readings: T + tau * slope (least squares over a window).

    Args:
        time_constant: the sensor's tau [s].
        window: number of readings for the slope (>= 2).
    """

    def __init__(self, time_constant: float, window: int = 5) -> None:
        self.tau = time_constant
        self.samples: Deque[Tuple[float, float]] = deque(maxlen=max(2, window))

    def update(self, reading: float, t: float) -> float:
        self.samples.append((t, reading))
        if len(self.samples) < self.samples.maxlen:      # warm-up: a short fit would amplify the noise
            return reading
        ts = np.array([s[0] for s in self.samples])
        vs = np.array([s[1] for s in self.samples])
        if np.ptp(ts) <= 0:
            return reading
        slope = np.polyfit(ts - ts[-1], vs, 1)[0]
        # the fitted line's value at the newest sample is less noisy than the raw reading
        level = np.polyval(np.polyfit(ts - ts[-1], vs, 1), 0.0)
        return float(level + self.tau * slope)
