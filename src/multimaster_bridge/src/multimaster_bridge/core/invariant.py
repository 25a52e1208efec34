"""The registration invariant of two bridged masters (ROS-free).

Each master's registrations of the other host's nodes (``/<peer>/<node>``, the proxies) must equal the other
master's own registrations that both bridges' allow/deny lists let across: the peer's exported ones (its filter)
that this host imports (its filter), each at the remote node's own XML-RPC URI (either spelling, with or without
the trailing slash). A service both hosts provide is served by one provider on both masters (newest wins): the
plain comparison already demands it, because a proxy hides the local provider in its master's answer.

Inputs are what the Master API answers (``getSystemState``, ``lookupNode``), so any tool that can reach both masters
can check it: :mod:`multimaster_bridge.watch` polls two masters and times each restore after an outage::

    side = MasterView.from_system_state(state, node_uris)
    problems = violations(Side('robot', robot_view, robot_filters), Side('cloud', cloud_view, cloud_filters))
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, NamedTuple, Optional, Set, Tuple

from multimaster_bridge.core.sync import Filter, proxy_name, same_node

KINDS = ('pub', 'sub', 'srv')


class Entry(NamedTuple):
    """One registration as its own host names it: kind (pub, sub, srv), topic or service, node."""
    kind: str
    name: str
    node: str


@dataclass(frozen=True)
class Filters:
    """A bridge's allow/deny lists (what it exports and imports)."""
    topics: Filter
    services: Filter

    def passes(self, kind: str, name: str) -> bool:
        return (self.services if kind == 'srv' else self.topics).passes(name)


@dataclass
class MasterView:
    """One master's registrations (getSystemState) and the URIs of the nodes that hold them (lookupNode)."""
    entries: Set[Entry] = field(default_factory=set)
    uris: Dict[str, str] = field(default_factory=dict)     # node -> XML-RPC URI, where known

    @classmethod
    def from_system_state(cls, state: Tuple[list, list, list],
                          uris: Optional[Dict[str, str]] = None) -> 'MasterView':
        entries = {Entry(kind, name, node) for kind, table in zip(KINDS, state)
                   for name, nodes in table for node in nodes}
        return cls(entries, dict(uris or {}))

    def nodes(self) -> Set[str]:
        return {e.node for e in self.entries}


@dataclass
class Side:
    """One host: its bridge's name (the prefix its peer gives its nodes), its master, its bridge's filters."""
    name: str
    view: MasterView
    filters: Filters


def _prefix(peer: str) -> str:
    return proxy_name(peer, '')


def own(side: Side, peer: str) -> Set[Entry]:
    """``side``'s registrations that are not proxies of ``peer``'s nodes."""
    prefix = _prefix(peer)
    return {e for e in side.view.entries if not e.node.startswith(prefix)}


def proxies(side: Side, peer: str) -> Set[Entry]:
    """``side``'s proxies of ``peer``'s nodes, under the names the peer gives them."""
    prefix = _prefix(peer)
    return {Entry(e.kind, e.name, '/' + e.node[len(prefix):]) for e in side.view.entries if e.node.startswith(prefix)}


def expected(here: Side, there: Side) -> Set[Entry]:
    """What ``here``'s master must hold of ``there``'s nodes: ``there``'s own registrations that ``there`` exports
    and ``here`` imports."""
    return {e for e in own(there, here.name)
            if there.filters.passes(e.kind, e.name) and here.filters.passes(e.kind, e.name)}


def _compare(a: Side, b: Side) -> List[Tuple[Side, Side, List[Entry], List[Entry], List[str]]]:
    """Per master (``here``, ``there``): the peer's entries it lacks, the proxies it has too many of, and its proxies
    at a URI that is not the node's (checked only where the registrations match and both views know the URI)."""
    out = []
    for here, there in ((a, b), (b, a)):
        want, have = expected(here, there), proxies(here, there.name)
        missing, extra = sorted(want - have), sorted(have - want)
        wrong_uri: List[str] = []
        if not missing and not extra:
            prefix = _prefix(there.name)
            for node in sorted({e.node for e in have}):
                at_there, at_here = there.view.uris.get(node), here.view.uris.get(prefix + node.lstrip('/'))
                if at_there is not None and at_here is not None and not same_node(at_there, at_here):
                    wrong_uri.append(f'{prefix}{node.lstrip("/")} at {at_here}, the node is at {at_there}')
        out.append((here, there, missing, extra, wrong_uri))
    return out


def violations(a: Side, b: Side) -> List[str]:
    """What is wrong with the registrations across between hosts ``a`` and ``b`` (empty: the invariant holds), one
    line per master. A proxy's URI is checked where both views know it."""
    wrong: List[str] = []
    for here, _, missing, extra, wrong_uri in _compare(a, b):
        if missing or extra:
            wrong.append(f'{here.name} master: missing {_short(missing)}, extra {_short(extra)}')
        wrong.extend(f'{here.name} master: {w}' for w in wrong_uri)
    return wrong


def discrepancies(a: Side, b: Side) -> List[str]:
    """The same as :func:`violations`, one line per registration (``robot master: missing pub /odom /simulator``,
    ``... extra ...``) or proxy URI: what a watch times one by one."""
    out: List[str] = []
    for here, _, missing, extra, wrong_uri in _compare(a, b):
        out.extend(f'{here.name} master: missing {e.kind} {e.name} {e.node}' for e in missing)
        out.extend(f'{here.name} master: extra {e.kind} {e.name} {e.node}' for e in extra)
        out.extend(f'{here.name} master: {w}' for w in wrong_uri)
    return out


def proxy_nodes(side: Side, peer: str) -> Set[str]:
    """The proxies' names in ``side``'s master (to look their URIs up)."""
    prefix = _prefix(peer)
    return {e.node for e in side.view.entries if e.node.startswith(prefix)}


def _short(entries: List[Entry], limit: int = 12) -> str:
    text = ', '.join(f'{e.kind} {e.name} {e.node}' for e in entries[:limit])
    more = f' and {len(entries) - limit} more' if len(entries) > limit else ''
    return f'[{text}{more}]'


__all__ = ['Entry', 'Filters', 'MasterView', 'Side', 'discrepancies', 'expected', 'own', 'proxies', 'proxy_nodes',
           'violations']
