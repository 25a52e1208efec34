"""Abnormal temperature detection (ROS-free).

``ambient`` mode: a value is abnormal when it exceeds ``ambient + delta``. ``statistics`` mode: when it is
``z`` standard deviations above the running mean of every measurement so far (after ``min_samples``) and at
least ``delta`` above it — the cell statistics the local mapcell manager keeps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict

from cnr_params import ConfigError, Section
from mfg.core.statecheck import state_section

MODES = ('ambient', 'statistics')


@dataclass
class DetectorConfig:
    mode: str
    ambient: float          # degC
    delta: float            # degC
    z: float                # standard deviations
    min_samples: int

    @classmethod
    def from_section(cls, sec: Section) -> 'DetectorConfig':
        """Parse ``{mode, ambient, delta, z, min_samples}`` (every field required; errors name it)."""
        return cls(mode=sec.string('mode', choices=MODES), ambient=sec.number('ambient'),
                   delta=sec.number('delta', positive=True), z=sec.number('z', positive=True),
                   min_samples=sec.integer('min_samples', minimum=2))


class Detector:
    def __init__(self, cfg: DetectorConfig) -> None:
        for name in ('ambient', 'delta', 'z'):
            if not math.isfinite(getattr(cfg, name)):
                raise ConfigError('mfg', f'threshold.{name}', 'must be finite')
        self.cfg = cfg
        self.n = 0
        self.mean = 0.0
        self.m2 = 0.0

    def observe(self, temperature: float) -> bool:
        """Feed one measurement; True if it is abnormal (judged before it joins the statistics)."""
        c = self.cfg
        if c.mode == 'ambient':
            abnormal = temperature > c.ambient + c.delta
        else:
            std = math.sqrt(self.m2 / (self.n - 1)) if self.n > 1 else math.inf
            abnormal = (self.n >= c.min_samples and temperature > self.mean + c.delta
                        and temperature > self.mean + c.z * std)
        if not abnormal:                       # abnormal values do not raise the baseline
            self.n += 1
            d = temperature - self.mean
            self.mean += d / self.n
            self.m2 += d * (temperature - self.mean)
        return abnormal

    # -- migration state (the package README, "Migration state") -----------------------------------------
    def state(self) -> Dict[str, Any]:
        """The threshold statistics: ``n`` measurements [count] judged normal, their ``mean`` [degC] and ``m2``
        (sum of squared deviations from the mean, [degC^2]; Welford)."""
        return {'n': self.n, 'mean': self.mean, 'm2': self.m2}

    def restore(self, state: Dict[str, Any], field: str = 'detector') -> None:
        """Take over :meth:`state` of another instance (the configuration stays this one's).

        Raises:
            ValueError: a key is missing or has a wrong type or value (the message names ``field.key``).
        """
        sec = state_section(state, field)
        n = sec.integer('n', minimum=0)
        mean = sec.number('mean')
        m2 = sec.number('m2', nonnegative=True)
        self.n, self.mean, self.m2 = n, mean, m2
