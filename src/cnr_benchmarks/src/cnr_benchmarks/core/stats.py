"""Summary statistics as the thesis's appendices give them (Appendix II and III).

The thesis reports, per column of 20 (RTT) or 5 (start-up) samples: average, sample standard
deviation (n - 1), sample size, confidence coefficient 1.96, margin of error, upper/lower bound,
max, min, range, variance, standard error (std / sqrt(n)) and median.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Dict, Iterable, Optional, Sequence

import numpy as np

CONFIDENCE_COEFFICIENT = 1.96


@dataclass(frozen=True)
class Summary:
    average: float
    std_dev: float
    sample_size: int
    margin_of_error: float
    upper_bound: float
    lower_bound: float
    max: float
    min: float
    range: float
    variance: float
    std_err: float
    median: float

    def as_dict(self) -> Dict[str, float]:
        return asdict(self)


def summarize(samples: Sequence[float]) -> Summary:
    """Statistics of ``samples`` (any unit; the result keeps it).

    Raises:
        ValueError: no samples, or a non-finite sample.
    """
    x = np.asarray(samples, dtype=float)
    if x.size == 0:
        raise ValueError('no samples')
    if not np.all(np.isfinite(x)):
        raise ValueError('non-finite sample')
    n = int(x.size)
    variance = float(x.var(ddof=1)) if n > 1 else 0.0
    std = math.sqrt(variance)
    err = std / math.sqrt(n)
    margin = CONFIDENCE_COEFFICIENT * err
    mean = float(x.mean())
    return Summary(average=mean, std_dev=std, sample_size=n, margin_of_error=margin,
                   upper_bound=mean + margin, lower_bound=mean - margin, max=float(x.max()),
                   min=float(x.min()), range=float(x.max() - x.min()), variance=variance,
                   std_err=err, median=float(np.median(x)))


def percentile(values: Iterable[Optional[float]], q: float) -> float:
    """The ``q``-th percentile (0..100, linear interpolation) of the finite ``values``; NaN when there are none."""
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.percentile(v, q)) if v else math.nan
