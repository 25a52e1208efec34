"""migration_manager settings from a :class:`cnr_params.Section` (config/migration.yaml, loaded into the
manager's, each agent's and each managed instance's ``~migration`` namespace). No defaults here: a missing
parameter is a one-line ConfigError naming it."""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Dict, Tuple

from cnr_params import Section

from migration_manager.core.lease import Grantor
from migration_manager.core.plan import Timeouts


@dataclass(frozen=True)
class LeaseSettings:
    duration: float
    renew_period: float
    margin: float
    authority_duration: float        # the same two for an instance on the authority's host (no link between it
    authority_renew_period: float    # and the grantor; its renewals may queue behind the saturated robot's work)
    paths: int                       # connections an instance on another host sends its renewals and gets its
                                     # answers over (one stalled by a lost packet does not starve the lease)

    def grantor(self, module: str, authority: str) -> Grantor:
        return Grantor(module, self.duration, self.margin, host_durations={authority: self.authority_duration})

    def renew_period_on(self, host: str, authority: str) -> float:
        return self.authority_renew_period if host == authority else self.renew_period

    def paths_on(self, host: str, authority: str) -> int:
        return 1 if host == authority else self.paths


@dataclass(frozen=True)
class MigrationConfig:
    hosts: Tuple[str, ...]
    authority: str
    modules: Tuple[str, ...]
    lease: LeaseSettings
    timeouts: Timeouts
    control_call: float
    replicate_period: float
    replicate_period_authority: float     # an active instance on the authority's host
    replicate_keyframe_every: int         # replicas between whole states (the others are patches)
    status_period: float
    failover: bool
    hot_standby: Tuple[str, ...]
    dormant: Dict[str, Tuple[str, ...]]   # module -> hosts where its instance, retired by a cold migration,
                                         # sleeps (kept for a quick wake-up) instead of being stopped
    stop_timeout: float
    restart_delay: float
    log_dir: str
    control_nice: int            # nice value of the manager and of the instances' protocol threads (cnr_runtime.priority)
    promotion_boost: float       # s every thread of a promoted instance runs at control_nice (0: none)
    bridge_poll_service: str     # this host's bridge's "poll now" service, called by an instance that became
                                 # active (its new registrations reach the other host at once); '' = none

    def other(self, host: str) -> str:
        return next(h for h in self.hosts if h != host)


def _names(s: Section, key: str, allowed: Tuple[str, ...] = ()) -> Tuple[str, ...]:
    value = s.raw(key)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise s.error(key, f'must be a list of names, got {value!r}')
    if len(set(value)) != len(value):
        raise s.error(key, 'names must not repeat')
    bad = [v for v in value if allowed and v not in allowed]
    if bad:
        raise s.error(key, f'{", ".join(bad)} not among {", ".join(allowed)}')
    return tuple(value)


def _managed(names: Tuple[str, ...], modules: Tuple[str, ...]) -> Tuple[str, ...]:
    """The names among the managed modules: a run that manages fewer (two_host --network-aware) ignores the rest."""
    return tuple(n for n in names if n in modules)


def _dormant(s: Section, modules: Tuple[str, ...], hosts: Tuple[str, ...]) -> Dict[str, Tuple[str, ...]]:
    value = s.raw('dormant')
    if not isinstance(value, dict):
        raise s.error('dormant', f'must map modules to lists of hosts, got {value!r}')
    out: Dict[str, Tuple[str, ...]] = {}
    for module, where in value.items():
        if not isinstance(module, str) or not module:
            raise s.error('dormant', f'keys must be module names, got {module!r}')
        if not isinstance(where, list) or not all(h in hosts for h in where):
            raise s.error('dormant', f'{module}: must be a list of hosts among {", ".join(hosts)}, got {where!r}')
        if module in modules:      # a run that manages fewer modules (two_host --network-aware) ignores the rest
            out[module] = tuple(where)
    return out


def from_section(s: Section) -> MigrationConfig:
    hosts = _names(s, 'hosts')
    if len(hosts) != 2:
        raise s.error('hosts', f'must name two hosts (robot and cloud), got {list(hosts)}')
    authority = s.string('authority', choices=hosts)
    modules = _names(s, 'modules')
    lease = s.section('lease')
    ls = LeaseSettings(duration=lease.number('duration', positive=True),
                       renew_period=lease.number('renew_period', positive=True),
                       margin=lease.number('margin', minimum=0.0),
                       authority_duration=lease.number('authority_duration', positive=True),
                       authority_renew_period=lease.number('authority_renew_period', positive=True),
                       paths=lease.integer('paths', minimum=1, maximum=8))
    for period, duration in (('renew_period', ls.duration), ('authority_renew_period', ls.authority_duration)):
        if getattr(ls, period) >= duration / 2:
            raise lease.error(period, f'must be below half the lease duration ({duration / 2:g} s), '
                                      f'got {getattr(ls, period):g}')
    t = s.section('timeouts')
    timeouts = Timeouts(start=t.number('start', positive=True), freeze=t.number('freeze', positive=True),
                        promote=t.number('promote', positive=True), replica=t.number('replica', minimum=0.0))
    agent = s.section('agent')
    log_dir = agent.string('log_dir')
    if not log_dir:
        raise agent.error('log_dir', 'must not be empty')
    return MigrationConfig(
        hosts=hosts, authority=authority, modules=modules, lease=ls, timeouts=timeouts,
        control_call=t.number('control_call', positive=True),
        replicate_period=s.number('replicate_period', positive=True),
        replicate_period_authority=s.number('replicate_period_authority', positive=True),
        replicate_keyframe_every=s.integer('replicate_keyframe_every', minimum=1),
        status_period=s.number('status_period', positive=True),
        failover=s.boolean('failover'), hot_standby=_managed(_names(s, 'hot_standby'), modules),
        dormant=_dormant(s, modules, hosts),
        stop_timeout=agent.number('stop_timeout', positive=True),
        restart_delay=agent.number('restart_delay', minimum=0.0),
        log_dir=os.path.abspath(os.path.expanduser(log_dir)),
        control_nice=s.integer('control_nice', minimum=-20, maximum=19),
        promotion_boost=s.number('promotion_boost', minimum=0.0),
        bridge_poll_service=_service_name(s, 'bridge_poll_service'))


def _service_name(s: Section, key: str) -> str:
    name = s.string(key)
    if name and not name.startswith('/'):
        raise s.error(key, f"must be a global name (/...) or '' (none), got {name!r}")
    return name
