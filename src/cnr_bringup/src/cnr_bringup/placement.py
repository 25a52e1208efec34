"""Which module runs where: the placement of the movable modules on the robot and the cloud (ROS-free).

One description (``config/placements.yaml``) serves the two-host mission's launch (which modules each host
starts), the bridges (what crosses the link) and the migration manager (the current placement)::

    catalog = load_catalog('config/placements.yaml')
    placement = catalog.placement('move_base_cloud')          # or a file with {module: host}
    placement.modules_on('cloud')                             # ['move_base']
    placement.allow('topics')                                 # topics used on both hosts
    placement.relayed()                                       # store-and-forward streams in use

A topic (service) crosses when modules on both hosts use it, so a placement with everything on the robot
bridges nothing but the ``always`` list. A stream listed under ``store_forward`` whose producer is on the
robot and whose consumer is on the cloud is carried by the store-and-forward relay instead of the bridge.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Tuple

from cnr_params.config import ConfigError, Section, load_yaml

KINDS = ('topics', 'services')


@dataclass(frozen=True)
class Module:
    """A module and the names it uses (topics and services, globs as written in the catalog)."""

    name: str
    topics: Tuple[str, ...]
    services: Tuple[str, ...]
    fixed_host: Optional[str] = None

    def names(self, kind: str) -> Tuple[str, ...]:
        return self.topics if kind == 'topics' else self.services


@dataclass(frozen=True)
class Stream:
    """A robot-made stream that a store-and-forward relay carries when its consumer is on the cloud."""

    stream: str
    topic: str
    producer: str
    consumer: str


@dataclass
class Placement:
    """A host for every module of a :class:`Catalog` (fixed ones included)."""

    name: str
    hosts: Dict[str, str]
    catalog: 'Catalog' = field(repr=False)
    managed: Tuple[str, ...] = ()       # modules the migration manager may move at run time (see managed_by)

    def managed_by(self, modules) -> 'Placement':
        """This placement as the *start* of a run in which ``modules`` may migrate: they count as present on
        every host for the bridges, a store-and-forward stream whose consumer is one of them is relayed (the
        consumer may be on the cloud at any time), and the launch files do not start them (the migration agents
        do)."""
        unknown = [m for m in modules if m not in self.catalog.movable]
        if unknown:
            raise ValueError(f"not movable: {', '.join(unknown)} (movable: {', '.join(self.catalog.movable)})")
        return Placement(self.name, dict(self.hosts), self.catalog, tuple(modules))

    def host(self, module: str) -> str:
        try:
            return self.hosts[module]
        except KeyError:
            raise KeyError(f"unknown module {module!r} (known: {', '.join(sorted(self.hosts))})") from None

    def modules_on(self, host: str) -> List[str]:
        """Movable modules placed on ``host`` (in catalog order)."""
        return [m for m in self.catalog.movable if self.hosts[m] == host]

    def remote(self) -> bool:
        """True when anything runs off the robot."""
        return any(h != self.catalog.hosts[0] for h in self.hosts.values())

    def relayed(self) -> List[Stream]:
        """The store-and-forward streams this placement needs: producer on the robot (never moved), consumer
        elsewhere or movable."""
        robot = self.catalog.hosts[0]
        return [s for s in self.catalog.streams if self.hosts[s.producer] == robot and s.producer not in self.managed
                and (self.hosts[s.consumer] != robot or s.consumer in self.managed)]

    def allow(self, kind: str) -> List[str]:
        """Names of ``kind`` (topics/services) that cross the link: used on more than one host."""
        if kind not in KINDS:
            raise ValueError(f'kind must be one of {KINDS}')
        used: Dict[str, set] = {}
        for module in self.catalog.modules.values():
            for name in module.names(kind):
                where = self.catalog.hosts if module.name in self.managed else (self.hosts[module.name],)
                used.setdefault(name, set()).update(where)
        names = [n for n, hosts in used.items() if len(hosts) > 1]
        names += [n for n in self.catalog.always[kind] if n not in names]
        if kind == 'topics':
            relayed = self.relayed()
            names = [n for n in names if n not in {s.topic for s in relayed}]
            names += [f'/store_forward/{s.stream}/*' for s in relayed]
        return sorted(names)

    def differs(self, other: 'Placement') -> Dict[str, Tuple[str, str]]:
        """Modules whose host differs: ``{module: (host here, host there)}`` (for a migration manager)."""
        return {m: (h, other.hosts[m]) for m, h in self.hosts.items() if other.hosts.get(m) != h}

    def as_dict(self) -> Dict[str, str]:
        return {m: self.hosts[m] for m in self.catalog.movable}


@dataclass
class Catalog:
    """The modules, hosts, relays and named placements of ``config/placements.yaml``."""

    source: str
    hosts: Tuple[str, ...]
    modules: Dict[str, Module]
    movable: Tuple[str, ...]
    always: Dict[str, Tuple[str, ...]]
    streams: Tuple[Stream, ...]
    named: Dict[str, Dict[str, str]]

    def placement(self, name_or_file: str) -> Placement:
        """A named placement, or one read from a YAML file holding ``{module: host}``."""
        if name_or_file in self.named:
            return self._build(name_or_file, self.named[name_or_file], self.source, f'placements.{name_or_file}')
        if name_or_file.endswith(('.yaml', '.yml')) or os.sep in name_or_file:
            data = load_yaml(name_or_file)
            return self._build(os.path.splitext(os.path.basename(name_or_file))[0], data, name_or_file, '')
        raise ConfigError(self.source, 'placements',
                          f"no placement named {name_or_file!r} (named: {', '.join(self.named)}; or give a file)")

    def _build(self, name: str, mapping: Mapping, source: str, prefix: str) -> Placement:
        hosts = {m: mod.fixed_host or self.hosts[0] for m, mod in self.modules.items()}
        for module, host in mapping.items():
            where = f'{prefix}.{module}' if prefix else str(module)
            if module not in self.modules:
                raise ConfigError(source, where, f"unknown module (movable: {', '.join(self.movable)})")
            if module not in self.movable:
                raise ConfigError(source, where, f'{module} never moves (fixed on {self.modules[module].fixed_host})')
            if host not in self.hosts:
                raise ConfigError(source, where, f"unknown host {host!r} (hosts: {', '.join(self.hosts)})")
            hosts[module] = host
        return Placement(name, hosts, self)


def _names(s: Section, key: str) -> Tuple[str, ...]:
    value = s.raw(key)
    if not isinstance(value, list) or not all(isinstance(v, str) and v.startswith('/') for v in value):
        raise s.error(key, "expected a list of absolute names ('/topic', globs allowed)")
    return tuple(value)


def load_catalog(path: str) -> Catalog:
    """Read and check ``config/placements.yaml`` (ConfigError naming file and field on a problem)."""
    s = Section.from_file(path)
    hosts = s.raw('hosts')
    if not (isinstance(hosts, list) and len(hosts) == 2 and all(isinstance(h, str) for h in hosts)):
        raise s.error('hosts', 'expected the two host names [robot, cloud]')
    modules: Dict[str, Module] = {}
    for key in ('fixed', 'modules'):
        group = s.section(key)
        for name in group.keys():
            m = group.section(name)
            fixed = m.string('host', choices=hosts) if key == 'fixed' else None
            modules[name] = Module(name, _names(m, 'topics'), _names(m, 'services'), fixed)
    movable = tuple(n for n, m in modules.items() if m.fixed_host is None)
    always_s = s.section('always')
    always = {k: _names(always_s, k) for k in KINDS}
    streams = []
    for i, st in enumerate(s.sections('store_forward')):
        stream = Stream(st.string('stream'), st.string('topic'), st.string('producer', choices=list(modules)),
                        st.string('consumer', choices=list(modules)))
        streams.append(stream)
    named: Dict[str, Dict[str, str]] = {}
    ps = s.section('placements')
    for name in ps.keys():
        value = ps.raw(name)
        if not isinstance(value, dict):
            raise ps.error(name, 'expected a mapping {module: host}')
        named[name] = dict(value)
    catalog = Catalog(path, tuple(hosts), modules, movable, always, tuple(streams), named)
    for name in named:
        catalog.placement(name)         # every named placement is valid
    return catalog


def launch_args(placement: Placement, host: str) -> List[str]:
    """``module:=true|false`` for each movable module (the launch files' arguments for ``host``); managed
    modules are started by the migration agents, not by the launch."""
    return [f'{m}:={str(placement.hosts[m] == host and m not in placement.managed).lower()}'
            for m in placement.catalog.movable]


def describe(placement: Placement) -> str:
    """A few lines for people: where each module runs and what crosses."""
    cat = placement.catalog
    lines = [f'placement {placement.name}:']
    for host in cat.hosts:
        mods = [m + ('*' if m in placement.managed else '') for m in cat.modules if placement.hosts[m] == host]
        lines.append(f"  {host:6s} {', '.join(mods) if mods else '-'}")
    if placement.managed:
        lines.append(f"  (* starts there; migration_manager may move it)")
    for kind in KINDS:
        lines.append(f"  bridged {kind}: {', '.join(placement.allow(kind)) or '-'}")
    relayed = placement.relayed()
    if relayed:
        lines.append('  store-and-forward: ' + ', '.join(f'{s.topic} ({s.producer} -> {s.consumer})' for s in relayed))
    return '\n'.join(lines)

