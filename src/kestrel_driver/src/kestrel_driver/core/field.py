"""Simulated air temperature: ambient plus Gaussian heat sources that may switch on and ramp up.

ROS-free. T(x, y, t) = ambient + sum_i peak_i * ramp_i(t) * exp(-d_i^2 / (2 radius_i^2)) [degC].
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List

from cnr_params import Section


@dataclass
class HeatSource:
    """A heater (or a hot rack exhaust).

    Attributes:
        name: label.
        x, y: position [m] (map frame).
        peak: temperature rise at the source [degC above ambient].
        radius: Gaussian standard deviation of the plume [m] (> 0).
        start: sim time when it switches on [s].
        ramp: time to reach full power after switching on [s] (0 = at once).
    """

    name: str
    x: float
    y: float
    peak: float
    radius: float
    start: float
    ramp: float

    def level(self, t: float) -> float:
        if t < self.start:
            return 0.0
        if self.ramp <= 0:
            return 1.0
        return min(1.0, (t - self.start) / self.ramp)


@dataclass
class TemperatureField:
    ambient: float
    sources: List[HeatSource]

    def at(self, x: float, y: float, t: float) -> float:
        """Air temperature at (x, y) at sim time t [degC]."""
        value = self.ambient
        for s in self.sources:
            lv = s.level(t)
            if lv > 0.0:
                d2 = (x - s.x) ** 2 + (y - s.y) ** 2
                value += s.peak * lv * math.exp(-d2 / (2.0 * s.radius ** 2))
        return value

    @classmethod
    def from_section(cls, sec: Section) -> 'TemperatureField':
        """Parse ``{ambient, sources: [{name, x, y, peak, radius, start, ramp}]}`` (all required; errors name the field).

        The one parser of heat sources: kestrel_driver and the scenario check (cnr_mission) both use it.
        """
        sources = []
        for s in sec.sections('sources'):
            sources.append(HeatSource(name=s.string('name'), x=s.number('x'), y=s.number('y'),
                                      peak=s.number('peak'), radius=s.number('radius', positive=True),
                                      start=s.number('start', nonnegative=True),
                                      ramp=s.number('ramp', nonnegative=True)))
        return cls(ambient=sec.number('ambient'), sources=sources)
