"""A simple configured placement rule (``run_mission.sh --rule``; network_monitor's learned k-NN decision is the other way).

From the link quality the robot's bridge measures (alive, RTT, heartbeat loss) it says where the rule's modules
should run: on the cloud while the link is *good* (RTT and loss below the good thresholds), on the robot while
it is *bad* (peer lost, or RTT or loss above the bad thresholds); in between, where they are (hysteresis). A
condition must hold for ``dwell`` seconds before it counts, and a module is not moved again within
``min_interval`` seconds of its last move (the migration budget) — except to the robot when the peer is lost,
which the manager's failover does at once anyway.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from cnr_params import Section


@dataclass(frozen=True)
class RuleConfig:
    modules: Tuple[str, ...]
    offload_to: str
    onload_to: str
    good_rtt: float            # [s] good: rtt < this and loss < good_loss
    good_loss: float           # [0..1]
    bad_rtt: float             # [s] bad: rtt > this or loss > bad_loss or peer lost
    bad_loss: float
    dwell: float               # [s]
    min_interval: float        # [s]


def rule_from_section(s: Section, modules: Tuple[str, ...], hosts: Tuple[str, ...], authority: str) -> RuleConfig:
    mods = s.raw('modules')
    if not isinstance(mods, list) or not all(m in modules for m in mods):
        raise s.error('modules', f'must list managed modules ({", ".join(modules)}), got {mods!r}')
    good, bad = s.section('good'), s.section('bad')
    cfg = RuleConfig(modules=tuple(mods), offload_to=s.string('offload_to', choices=[h for h in hosts if h != authority]),
                     onload_to=authority,
                     good_rtt=good.number('rtt_below', positive=True), good_loss=good.number('loss_below', minimum=0.0),
                     bad_rtt=bad.number('rtt_above', positive=True), bad_loss=bad.number('loss_above', minimum=0.0),
                     dwell=s.number('dwell', nonnegative=True), min_interval=s.number('min_interval', nonnegative=True))
    if cfg.bad_rtt < cfg.good_rtt:
        raise bad.error('rtt_above', f'must be >= good.rtt_below ({cfg.good_rtt:g}) for the hysteresis band')
    if cfg.bad_loss < cfg.good_loss:
        raise bad.error('loss_above', f'must be >= good.loss_below ({cfg.good_loss:g})')
    return cfg


class PlacementRule:
    def __init__(self, cfg: RuleConfig) -> None:
        self.cfg = cfg
        self.state = 'unknown'           # good | bad | between
        self.since = -math.inf           # when the current state began
        self.last_move: Dict[str, float] = {}

    def classify(self, alive: bool, rtt: float, loss: float) -> str:
        c = self.cfg
        if not alive or (math.isfinite(rtt) and rtt > c.bad_rtt) or loss > c.bad_loss:
            return 'bad'
        if math.isfinite(rtt) and rtt < c.good_rtt and loss < c.good_loss:
            return 'good'
        return 'between'

    def observe(self, now: float, alive: bool, rtt: float, loss: float) -> None:
        state = self.classify(alive, rtt, loss)
        if state != self.state:
            self.state, self.since = state, now

    def wanted(self, now: float) -> Optional[str]:
        """The host the rule's modules should be on now (None: no opinion yet, or in the hysteresis band)."""
        if now - self.since < self.cfg.dwell:
            return None
        return {'good': self.cfg.offload_to, 'bad': self.cfg.onload_to}.get(self.state)

    def orders(self, now: float, placement: Dict[str, str]) -> List[Tuple[str, str]]:
        """(module, target) for each rule module not where it should be and within its budget."""
        target = self.wanted(now)
        if target is None:
            return []
        out = []
        for m in self.cfg.modules:
            host = placement.get(m, '')
            if not host or host == target:
                continue                 # migrating (no active instance) or already there
            if now - self.last_move.get(m, -math.inf) < self.cfg.min_interval and target != self.cfg.onload_to:
                continue
            out.append((m, target))
        return out

    def moved(self, module: str, now: float) -> None:
        self.last_move[module] = now
