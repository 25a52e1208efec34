"""The migration decision before a task: k-nearest neighbours (thesis §4.2.5, Eq. 4-2..4-4) with scikit-learn.

Features. A network profile (C_l = RTT [s], R_bw = A_bw / C_bw) becomes a point in the unit square::

    x = min(C_l, rtt_max) / rtt_max
    y = log10(clip(R_bw, r_bw_min, r_bw_max) / r_bw_min) / log10(r_bw_max / r_bw_min)

Both axes run 0..1, so Eq. 4-3's Euclidean distance weighs latency and bandwidth alike (the thesis normalised
and chose R_bw's direction for the same reason, §4.2.4). R_bw is compared on a log scale: it is a ratio that
spans decades (an idle link gives A_bw / c_bw_floor: up to 250 on a 50 Mbit/s link), and what matters is the
factor of headroom — 2 vs 4 is as different as 50 vs 100, while 200 vs 2000 are both "plenty". Beyond the clips every
value is equally bad (RTT >= rtt_max, R_bw <= r_bw_min: the link is saturated) or equally good
(R_bw >= r_bw_max).

k-NN. ``sklearn.neighbors.KNeighborsClassifier(n_neighbors=k, metric='euclidean', weights='uniform',
algorithm='brute')`` fitted on the rows' *labels* (the placement that should have been chosen,
evaluation.label_for), not on the decisions that were run. k must be odd (the configuration refuses even k):
Eq. 4-4 is undefined at exactly k/2 votes, and with two classes and an odd k there is never a tie.

Cold start. With fewer than k rows the k-NN has no k neighbours; a rule decides: offload iff C_l < rule RTT
and R_bw > rule R_bw, else onload.

Exploration (epsilon-greedy). Every decision with a known profile draws one number from the decider's
``random.Random``; below ``rate`` the other placement than the policy's (k-NN or cold start) is run, so both
placements keep getting data and a wrong region can be corrected. An offload is never explored when
C_l >= ``max_rtt`` (the thesis's move_base stopped moving at about 160 ms).

Unknown profile (C_l or R_bw NaN, e.g. no pong, no A_bw yet): onload, reason ``no_profile``, no exploration.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

from sklearn.neighbors import KNeighborsClassifier
from threadpoolctl import threadpool_limits

from network_monitor.core.evaluation import OFFLOAD, ONLOAD, other
from network_monitor.core.training import Row

KNN = 'knn'
COLD_START = 'cold_start'
EXPLORE = 'explore'
NO_PROFILE = 'no_profile'


@dataclass(frozen=True)
class Normalisation:
    rtt_max: float          # s; RTTs at or above map to x = 1
    r_bw_min: float         # R_bw at or below maps to y = 0 (> 0)
    r_bw_max: float         # R_bw at or above maps to y = 1 (> r_bw_min)

    def point(self, c_l: float, r_bw: float) -> Tuple[float, float]:
        """(x, y) in [0, 1]^2 for C_l [s] and R_bw (module docstring)."""
        x = min(max(c_l, 0.0), self.rtt_max) / self.rtt_max
        r = min(max(r_bw, self.r_bw_min), self.r_bw_max)
        y = math.log10(r / self.r_bw_min) / math.log10(self.r_bw_max / self.r_bw_min)
        return x, y


@dataclass(frozen=True)
class ColdStartRule:
    rtt: float              # s; offload only below this RTT
    r_bw: float             # offload only above this R_bw

    def decide(self, c_l: float, r_bw: float) -> str:
        return OFFLOAD if c_l < self.rtt and r_bw > self.r_bw else ONLOAD


@dataclass(frozen=True)
class Exploration:
    rate: float             # 0..0.5, probability of running the other placement
    max_rtt: float          # s; no exploratory offload at or above this RTT
    seed: Optional[int]     # random.Random seed; None = from the OS


@dataclass(frozen=True)
class DecisionSettings:
    k: int                  # odd, >= 1
    normalisation: Normalisation
    cold_start: ColdStartRule
    exploration: Exploration


@dataclass(frozen=True)
class Neighbour:
    index: int              # the row's index in the training rows
    c_l: float
    r_bw: float
    point: Tuple[float, float]
    label: str
    distance: float         # Eq. 4-3, in normalised units


@dataclass(frozen=True)
class Decision:
    decision: str                       # offload | onload: what to run
    reason: str                         # knn | cold_start | explore | no_profile
    policy: str                         # what k-NN or the cold-start rule chose (== decision unless explore)
    votes: Dict[str, int]               # k-NN votes {offload: n, onload: k - n}; empty unless k-NN ran
    neighbours: Tuple[Neighbour, ...]   # the k nearest rows, nearest first; empty unless k-NN ran
    point: Tuple[float, float]          # the normalised (x, y); NaNs with no_profile
    confidence: float                   # votes for ``decision`` / k (knn, explore; 0 for an exploration
                                        # during cold start); 1.0 for cold_start and no_profile (a rule)


class Decider:
    """k-NN over one ⟨task, location⟩'s training rows, with cold start and exploration.

    Args:
        settings: k, normalisation, cold-start rule, exploration.
        rows: the training rows (all of them are used; only their c_l, r_bw and label matter).
        rng: the exploration's random source; default ``random.Random(settings.exploration.seed)``.
    """

    def __init__(self, settings: DecisionSettings, rows: Sequence[Row], rng: Optional[random.Random] = None) -> None:
        if settings.k < 1 or settings.k % 2 == 0:
            raise ValueError(f'k must be odd and >= 1, got {settings.k}')
        self.settings = settings
        self.rng = rng if rng is not None else random.Random(settings.exploration.seed)
        self.rows: List[Row] = []
        self.points: List[Tuple[float, float]] = []
        self._knn: Optional[KNeighborsClassifier] = None
        self.retrain(rows)

    def retrain(self, rows: Sequence[Row]) -> None:
        """Replace the training rows (e.g. after a new row was appended)."""
        self.rows = list(rows)
        self.points = [self.settings.normalisation.point(r.c_l, r.r_bw) for r in self.rows]
        self._knn = None
        if len(self.rows) >= self.settings.k:
            self._knn = KNeighborsClassifier(n_neighbors=self.settings.k, metric='euclidean', weights='uniform',
                                             algorithm='brute')
            self._knn.fit(self.points, [r.label for r in self.rows])

    @property
    def cold(self) -> bool:
        """True while there are fewer than k rows (the cold-start rule decides)."""
        return self._knn is None

    def policy(self, c_l: float, r_bw: float) -> Decision:
        """The k-NN's (or the cold-start rule's) decision, without exploration."""
        if math.isnan(c_l) or math.isnan(r_bw):
            return Decision(ONLOAD, NO_PROFILE, ONLOAD, {}, (), (math.nan, math.nan), 1.0)
        point = self.settings.normalisation.point(c_l, r_bw)
        if self._knn is None:
            d = self.settings.cold_start.decide(c_l, r_bw)
            return Decision(d, COLD_START, d, {}, (), point, 1.0)
        # one thread: scikit-learn's brute-force neighbour search runs an OpenMP team whose threads spin-wait, and
        # on the robot's computer (a CPU quota, throttled most of the time during a task) one call of a few
        # microseconds' work then costs ~40 ms of CPU; the robot re-decides on every network profile (2 Hz)
        with threadpool_limits(limits=1, user_api='openmp'):
            decision = str(self._knn.predict([point])[0])
            distances, indices = self._knn.kneighbors([point])
        neighbours = tuple(Neighbour(index=int(i), c_l=self.rows[i].c_l, r_bw=self.rows[i].r_bw,
                                     point=self.points[i], label=self.rows[i].label, distance=float(dist))
                           for dist, i in zip(distances[0], indices[0]))
        votes = {OFFLOAD: sum(1 for n in neighbours if n.label == OFFLOAD),
                 ONLOAD: sum(1 for n in neighbours if n.label == ONLOAD)}
        return Decision(decision, KNN, decision, votes, neighbours, point, votes[decision] / self.settings.k)

    def decide(self, c_l: float, r_bw: float) -> Decision:
        """The decision before a task for C_l [s] (RTT) and R_bw (ratio): the policy, or with probability
        ``exploration.rate`` the other placement (module docstring)."""
        d = self.policy(c_l, r_bw)
        if d.reason == NO_PROFILE:
            return d
        ex = self.settings.exploration
        if self.rng.random() >= ex.rate:
            return d
        alternative = other(d.decision)
        if alternative == OFFLOAD and c_l >= ex.max_rtt:
            return d
        confidence = d.votes[alternative] / self.settings.k if d.votes else 0.0
        return Decision(alternative, EXPLORE, d.decision, d.votes, d.neighbours, d.point, confidence)
