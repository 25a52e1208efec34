"""Registration sync between masters: what to export, what to register, what to remove (ROS-free).

A bridge polls its own master into a :class:`Snapshot`, exports the entries that pass its filters and are
not its own proxies (:func:`export_state`), and pushes that state to its peers. A peer turns a received
state into the set of :class:`Registration` it wants in its own master (:func:`plan`) and applies the
difference to what it registered before (:func:`diff`).

Rules (see the package README):

* **Deny by default**: a topic or service is exported and imported only if it matches an allow glob and
  no deny glob.
* **Bridge-owned identities**: remote node ``/talker`` of peer ``cloud`` is registered as
  ``/cloud/talker`` with the remote node's own XML-RPC URI, so nodes still connect directly over TCPROS
  but a proxy can never take the name of a local node ("new node registered with same name"). A proxy
  whose name is taken by a local node is skipped and reported.
* **Type and md5 checks**: a remote topic whose type or md5sum differs from the local one is rejected.
* **Services, newest provider wins**: a service on both hosts is served by the provider registered last,
  so a module started on the other host takes over before the old one stops (make-before-break). A service
  proxy the master no longer lists is registered again (:func:`displaced`): a local node that opened the service
  over it and closed it again (a standby's reconfigure server) left the service with no provider at all.
* **Forced reconnect**: after a peer was lost, its nodes are registered under the other spelling of their
  URI (with or without the trailing slash). rospy subscribers connect again (they skip a URI they are
  already connected to, even over a dead TCP link) and the publisher drops the stale connection.
  Unless the master still holds the node under the old spelling (:func:`kept_spellings`): rosmaster keeps a
  node's entry while it lists any registration, and a proxy's service that a newer local provider took over
  stays listed for ever (its unregistration no longer matches). Registering the other spelling then makes
  rosmaster shut down "the old node" — the old spelling is the remote node's own URI, so the real node on the
  other host would be told to exit. Such a node keeps the master's spelling.
* **An outage in one direction** stalls the connections both ways, but only one bridge loses its peer: the
  other reconnects the peer's nodes when the peer's heartbeats say it heard us again
  (:func:`rejoined_without_our_loss`).
* **In-order topics keep their connection**: a forced reconnect gives a subscriber a second connection to the
  same publisher while the first still holds what the publisher sent during the outage; TCP delivers that
  backlog when it next retransmits, seconds after the new connection brought fresh messages, so the subscriber
  gets old messages after new ones. On ``/clock`` that is time going backwards (rospy raises
  ROSTimeMovedBackwardsException in every sleeping thread of a sim-time node). A remote node that publishes a
  topic of the ``in_order`` filter therefore keeps its URI spelling (:func:`in_order_publishers`): its
  subscribers resume on the old connection, backlog first, in order.
"""
from __future__ import annotations

import fnmatch
import hashlib
import json
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, NamedTuple, Optional, Set, Tuple


class Filter:
    """Allow/deny globs for one kind of name (fnmatch syntax, ``*`` also matches ``/``)."""

    MEMO_LIMIT = 4096   # names remembered; the memo starts afresh beyond (a graph that churns names)

    def __init__(self, allow: Iterable[str] = (), deny: Iterable[str] = ()) -> None:
        self.allow = list(allow)
        self.deny = list(deny)
        self._memo: Dict[str, bool] = {}

    def passes(self, name: str) -> bool:
        """Memoised: the bridge asks about every name of its master at every poll, and a name's answer
        never changes (matching ~25 globs per name was a third of a poll's CPU)."""
        verdict = self._memo.get(name)
        if verdict is None:
            if len(self._memo) >= self.MEMO_LIMIT:
                self._memo.clear()
            verdict = self._memo[name] = (any(fnmatch.fnmatchcase(name, g) for g in self.allow)
                                          and not any(fnmatch.fnmatchcase(name, g) for g in self.deny))
        return verdict


@dataclass
class Snapshot:
    """A master's registrations (from getSystemState, getTopicTypes, lookupNode, lookupService)."""
    pubs: Dict[str, Set[str]] = field(default_factory=dict)      # topic -> node names
    subs: Dict[str, Set[str]] = field(default_factory=dict)      # topic -> node names
    services: Dict[str, str] = field(default_factory=dict)       # service -> provider node
    service_apis: Dict[str, str] = field(default_factory=dict)   # service -> rosrpc URI
    types: Dict[str, str] = field(default_factory=dict)          # topic -> type
    nodes: Dict[str, str] = field(default_factory=dict)          # node -> XML-RPC URI

    @classmethod
    def from_system_state(cls, state: Tuple[list, list, list], types: Iterable[Tuple[str, str]]) -> 'Snapshot':
        pubs, subs, srvs = state
        snap = cls()
        snap.pubs = {t: set(n) for t, n in pubs}
        snap.subs = {t: set(n) for t, n in subs}
        snap.services = {s: n[0] for s, n in srvs if n}
        snap.types = dict(types)
        return snap

    def node_names(self) -> Set[str]:
        names: Set[str] = set(self.services.values())
        for table in (self.pubs, self.subs):
            for nodes in table.values():
                names |= nodes
        return names


class Registration(NamedTuple):
    """One entry the bridge owns in its master. ``extra`` is the topic type or the service URI."""
    kind: str        # 'pub' | 'sub' | 'srv'
    name: str        # topic or service
    caller_id: str   # bridge-owned name, e.g. /cloud/talker
    caller_api: str  # the remote node's XML-RPC URI (possibly the other spelling)
    extra: str


def proxy_name(peer: str, node: str) -> str:
    """``/cloud`` + ``/talker`` -> ``/cloud/talker``."""
    return '/' + peer.strip('/') + '/' + node.lstrip('/')


def uri_spelling(uri: str, generation: int) -> str:
    """The node URI as registered in generation ``generation``: even = as given, odd = the other spelling.

    ``http://h:1234/`` and ``http://h:1234`` reach the same XML-RPC server, but rospy's subscriber
    treats them as two publishers and dials a fresh TCPROS connection.
    """
    base = uri.rstrip('/')
    canonical_slash = uri.endswith('/')
    with_slash = canonical_slash if generation % 2 == 0 else not canonical_slash
    return base + '/' if with_slash else base


def same_node(uri_a: str, uri_b: str) -> bool:
    """Whether two XML-RPC URIs are spellings of one node's (with or without the trailing slash)."""
    return uri_a.rstrip('/') == uri_b.rstrip('/')


def is_proxy(node: str, peers: Iterable[str]) -> bool:
    """Whether ``node`` has the name of a proxy of one of ``peers``' nodes (``/<peer>/...``)."""
    return any(node.startswith(proxy_name(p, '')) for p in peers)


ServiceKey = Tuple[str, str, str]   # (service, provider node, service URI)


def service_ages(first_seen: Dict[ServiceKey, float], listed: Dict[str, Tuple[str, str]],
                 hidden: Dict[str, Tuple[str, str]], now: float) -> Tuple[Dict[ServiceKey, float], Dict[str, float]]:
    """How long each service's provider has been registered, for newest-provider-wins.

    Args:
        first_seen: (service, node, service URI) -> when that provider was first seen (the previous result).
        listed: service -> (node, service URI) of its provider in the master now (a proxy, possibly).
        hidden: service -> (node, service URI) of a local provider that a proxy hides in the master.
        now: the time of the poll.

    Returns:
        (first_seen to pass next time, service -> age of its listed provider [s]). A local provider keeps its first
        sighting while a proxy hides it: when the proxy goes (the peer was lost) and the provider serves again, it
        is as old as it was, and a newer remote provider still wins when the peer returns.
    """
    keys = {(s,) + p for s, p in listed.items()} | {(s,) + p for s, p in hidden.items()}
    kept = {k: first_seen.get(k, now) for k in keys}
    return kept, {s: now - kept[(s,) + p] for s, p in listed.items()}


def displaced(registered: Iterable[Registration], snap: Snapshot,
              owned: Set[str]) -> Tuple[Set[Registration], Dict[str, str]]:
    """The service proxies of ``registered`` that ``snap`` (the master after them) no longer lists as providers.

    rosmaster keeps one provider per service: a local node that registers a service a proxy serves takes it over,
    and when that node unregisters it again (a standby's reconfigure server, opened and closed at start-up) the
    service is gone from the master although the bridge still counts its proxy as registered. ``owned``: the
    bridge's proxies. Returns (the proxies no longer listed, to be counted as not registered: those whose service
    has no provider or another one; service -> the local node listed instead, where one is). A local node listed
    over a proxy registered it after the proxy, so it is the newest provider (the caller restarts its age)."""
    gone: Set[Registration] = set()
    taken: Dict[str, str] = {}
    for r in registered:
        if r.kind != 'srv':
            continue
        provider = snap.services.get(r.name)
        if provider == r.caller_id:
            continue
        gone.add(r)
        if provider is not None and provider not in owned and provider in snap.nodes:
            taken[r.name] = provider
    return gone, taken


def aged_state(state: dict, elapsed: float) -> dict:
    """A peer's ``state`` as of ``elapsed`` seconds after it was sent: its services' providers that much older.

    A peer sends its state again only when its digest changes, and the digest leaves the ages out (they change at
    every poll), so a state kept for a minute says its providers are a minute younger than they are: compared with a
    local provider's current age, the older provider would win (the two bridges would take turns hiding theirs)."""
    if elapsed <= 0 or not state.get('srvs'):
        return state
    return dict(state, srvs={s: [node, api, age + elapsed] for s, (node, api, age) in state['srvs'].items()})


def rejoined_without_our_loss(view_before: Optional[bool], view_now: bool, since_our_return: float,
                              loss_timeout: float) -> bool:
    """Whether a peer's heartbeat says it lost us and hears us again while we did not lose it: an outage in one
    direction. Our subscribers' connections to its publishers stalled as well (their data or their ACKs were
    lost), so its nodes are reconnected here too (a new generation). ``view_before``/``view_now``: whether the
    peer considered us alive in its previous and in this heartbeat; ``since_our_return``: seconds since we heard
    the peer again after losing it ourselves. Within ``loss_timeout`` of that the peer's return belongs to the
    same outage, which our own loss already reconnected (a second generation would restore the old spelling)."""
    return view_before is False and view_now and since_our_return > loss_timeout


def in_order_publishers(state: dict, in_order: Filter) -> Set[str]:
    """The nodes of a peer's ``state`` that publish a topic whose subscribers must get its messages in order."""
    return {n for topic, nodes in state.get('pubs', {}).items() if in_order.passes(topic) for n in nodes}


def export_state(snap: Snapshot, owned: Set[str], topics: Filter, services: Filter,
                 ages: Dict[str, float], md5s: Dict[str, str]) -> dict:
    """The part of ``snap`` a peer may import: filtered, without the bridge's own proxies.

    Args:
        owned: caller_ids of the bridge's proxies (never exported back: no echo).
        ages: service -> seconds since its current provider was first seen (for newest-wins).
        md5s: type -> md5sum where the message class is known locally.
    """
    def local(nodes: Set[str]) -> List[str]:
        return sorted(n for n in nodes if n not in owned and n in snap.nodes)

    pubs = {t: local(n) for t, n in snap.pubs.items() if topics.passes(t)}
    subs = {t: local(n) for t, n in snap.subs.items() if topics.passes(t)}
    pubs = {t: n for t, n in pubs.items() if n and t in snap.types}
    subs = {t: n for t, n in subs.items() if n}
    srvs = {s: [n, snap.service_apis[s], round(ages.get(s, 0.0), 3)]
            for s, n in snap.services.items()
            if services.passes(s) and n not in owned and n in snap.nodes and s in snap.service_apis}
    used = {n for v in pubs.values() for n in v} | {n for v in subs.values() for n in v} | \
        {v[0] for v in srvs.values()}
    types = {t: snap.types.get(t, '*') for t in set(pubs) | set(subs)}
    return {'pubs': pubs, 'subs': subs, 'srvs': srvs, 'types': types,
            'md5': {ty: md5s[ty] for ty in set(types.values()) if ty in md5s},
            'nodes': {n: snap.nodes[n] for n in sorted(used)}}


def digest(state: dict) -> str:
    """Stable digest of an exported state (services' ages excluded: they change every poll)."""
    stable = dict(state)
    stable['srvs'] = {s: v[:2] for s, v in state.get('srvs', {}).items()}
    return hashlib.sha1(json.dumps(stable, sort_keys=True).encode()).hexdigest()[:16]


@dataclass
class Plan:
    registrations: Set[Registration]
    problems: List[str]


def plan(peer: str, state: dict, local: Snapshot, owned: Set[str], topics: Filter, services: Filter,
         local_ages: Dict[str, float], md5s: Dict[str, str], generation: int = 0,
         in_order: Optional[Filter] = None) -> Plan:
    """The registrations of ``peer``'s ``state`` this bridge wants in its master.

    Args:
        local: the local master now (including the bridge's proxies).
        owned: caller_ids of the bridge's proxies.
        local_ages: service -> age of its local provider [s], for newest-provider-wins.
        md5s: type -> local md5sum.
        generation: reconnect generation of this peer (selects the URI spelling).
        in_order: topics whose publishers keep their URI spelling in every generation (no forced reconnect).
    """
    out: Set[Registration] = set()
    problems: List[str] = []
    nodes: Dict[str, str] = state.get('nodes', {})
    types: Dict[str, str] = state.get('types', {})
    remote_md5: Dict[str, str] = state.get('md5', {})
    steady = in_order_publishers(state, in_order) if in_order is not None else set()

    def identity(node: str) -> Optional[Tuple[str, str]]:
        uri = nodes.get(node)
        if not uri:
            return None
        cid = proxy_name(peer, node)
        if cid in local.nodes and cid not in owned and not same_node(local.nodes[cid], uri):
            problems.append(f'{peer}: node {node} not imported: local node {cid} has that name')
            return None
        return cid, uri_spelling(uri, 0 if node in steady else generation)

    def topic_ok(topic: str) -> bool:
        if not topics.passes(topic):
            return False
        rtype = types.get(topic, '*')
        ltype = local.types.get(topic)
        if rtype != '*' and ltype not in (None, '*', rtype):
            problems.append(f'{peer}: topic {topic} rejected: type {rtype} there, {ltype} here')
            return False
        if rtype in remote_md5 and rtype in md5s and remote_md5[rtype] != md5s[rtype]:
            problems.append(f'{peer}: topic {topic} rejected: {rtype} md5 {remote_md5[rtype]} there, '
                            f'{md5s[rtype]} here')
            return False
        return True

    for kind, table in (('pub', state.get('pubs', {})), ('sub', state.get('subs', {}))):
        for topic, node_list in table.items():
            if not topic_ok(topic):
                continue
            for node in node_list:
                ident = identity(node)
                if ident:
                    out.add(Registration(kind, topic, ident[0], ident[1], types.get(topic, '*')))

    for service, (node, service_api, age) in state.get('srvs', {}).items():
        if not services.passes(service):
            continue
        provider = local.services.get(service)
        if provider is not None and provider not in owned and local_ages.get(service, 0.0) <= age:
            continue  # a local provider registered after the remote one: it wins
        ident = identity(node)
        if ident:
            out.add(Registration('srv', service, ident[0], ident[1], service_api))
    return Plan(out, problems)


def diff(current: Set[Registration], desired: Set[Registration]) -> Tuple[List[Registration], List[Registration]]:
    """(to unregister, to register): unregistrations first, so a node's URI spelling never changes in place."""
    return sorted(current - desired), sorted(desired - current)


def kept_spellings(wanted: Dict[str, str], known: Dict[str, str]) -> Dict[str, str]:
    """caller_id -> the URI the master still holds for it, where that is another spelling of the URI ``wanted``
    would register (``known``: the master's lookupNode answers). Registering ``wanted``'s spelling would make
    rosmaster shut the node down at the spelling it holds, which is the remote node itself."""
    return {cid: known[cid] for cid, api in wanted.items()
            if cid in known and known[cid] != api and known[cid].rstrip('/') == api.rstrip('/')}


def respell(registrations: Iterable[Registration], apis: Dict[str, str]) -> Set[Registration]:
    """``registrations`` with each caller_id in ``apis`` registered at that URI instead, where that URI is a
    spelling of the same node's. A remote node started again (another port, same name) is registered at its new
    URI: a kept spelling of the old process must not keep its proxy pointing at a dead node."""
    return {r._replace(caller_api=apis[r.caller_id])
            if r.caller_id in apis and same_node(apis[r.caller_id], r.caller_api) else r for r in registrations}


def must_wait(held: Optional[str], wanted: str) -> bool:
    """Whether a proxy's registration at ``wanted`` waits until the master no longer holds its caller_id at
    ``held``: only for a change of spelling of one node (registering it would make rosmaster shut down the URI it
    holds, the real node). A remote node started again at a new URI is registered at once: rosmaster then tells the
    old process, gone or replaced on its own host, to shut down, and drops the entry that a registration of it no
    longer removable (a service a local provider took over) would otherwise keep for ever."""
    return held is not None and held != wanted and same_node(held, wanted)


def respell_in_place(unregister: Iterable[Registration], register: Iterable[Registration],
                     keep: Iterable[Registration], snap: Snapshot, unlisted: Dict[str, str]) -> Set[str]:
    """caller_ids whose URI spelling changes (:func:`must_wait`) and may change within one batch: all their
    registrations removed, then registered again at the new spelling. rosmaster drops a node from its table when
    its last registration goes, so the new spelling is then a new node, never a change that shuts the real one
    down. That holds only when the batch removes every registration the master holds of it: none kept
    (``keep``), none that ``snap`` lists outside ``unregister``, and none the master holds without listing it
    (``unlisted``: caller_id -> URI, a service proxy a local provider took over or that went with one: rosmaster
    keeps the key in the node's entry for good). Those wait for a poll as before."""
    apis: Dict[str, Set[str]] = {}
    for r in register:
        apis.setdefault(r.caller_id, set()).add(r.caller_api)
    kept = {r.caller_id for r in keep}
    candidates = {cid for cid, wanted in apis.items()
                  if len(wanted) == 1 and cid not in kept and must_wait(snap.nodes.get(cid), next(iter(wanted)))
                  and not (cid in unlisted and same_node(unlisted[cid], next(iter(wanted))))}
    if not candidates:          # every reconcile but a forced reconnect's: the snapshot is not walked
        return set()
    removed = {(r.kind, r.name, r.caller_id) for r in unregister}
    listed = [(kind, name, node) for kind, table in (('pub', snap.pubs), ('sub', snap.subs))
              for name, nodes in table.items() for node in nodes if node in candidates]
    listed += [('srv', name, node) for name, node in snap.services.items() if node in candidates]
    return candidates - {node for kind, name, node in listed if (kind, name, node) not in removed}


def batch_order(unregister: List[Registration], register: List[Registration],
                in_place: Set[str]) -> List[Tuple[bool, Registration]]:
    """The calls of one batch as (register?, registration): the removals first (a peer's subscribers and services
    before its publishers), then each node of ``in_place`` removed and at once registered again (its registrations
    are off the master only for its own few calls), then the other registrations."""
    removals = sorted(unregister, key=lambda r: r.kind == 'pub')
    calls: List[Tuple[bool, Registration]] = [(False, r) for r in removals if r.caller_id not in in_place]
    for cid in sorted(in_place):
        calls += [(False, r) for r in removals if r.caller_id == cid]
        calls += [(True, r) for r in register if r.caller_id == cid]
    calls += [(True, r) for r in register if r.caller_id not in in_place]
    return calls


def conflicting_identities(to_register: Iterable[Registration], keep: Iterable[Registration]) -> Set[str]:
    """caller_ids that would be registered with two different URIs at once (must wait for removals)."""
    apis: Dict[str, Set[str]] = {}
    for reg in list(to_register) + list(keep):
        apis.setdefault(reg.caller_id, set()).add(reg.caller_api)
    return {cid for cid, a in apis.items() if len(a) > 1}
