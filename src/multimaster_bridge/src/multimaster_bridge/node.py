"""The ``bridge`` node: joins this host's rosmaster with its peers' (see the package README).

ROS I/O only: the sync rules are in :mod:`multimaster_bridge.core.sync`, the wire format in
:mod:`multimaster_bridge.core.protocol`, link estimation in :mod:`multimaster_bridge.core.heartbeat`.
"""
from __future__ import annotations

import gzip
import math
import socket
import threading
import time
import xmlrpc.client
from typing import Dict, List, Optional, Set, Tuple

import rosgraph
import rospy

from cnr_msgs.msg import LinkQuality
from cnr_params import exit_on_config_error
from cnr_params.ros import private_section
from cnr_runtime import init_node
from cnr_runtime.priority import Elevator
from std_srvs.srv import Empty, EmptyResponse
from multimaster_bridge.core import config as bridge_config
from multimaster_bridge.core import protocol, sync
from multimaster_bridge.core.heartbeat import LinkEstimator

MAX_DATAGRAM = 65000


class PeerState:
    def __init__(self, peer: bridge_config.Peer, cfg: bridge_config.BridgeConfig) -> None:
        self.peer = peer
        self.estimator = LinkEstimator(cfg.heartbeat_rate, cfg.loss_timeout)
        self.alive = False
        self.state: Optional[dict] = None
        self.state_at = 0.0                         # when ``state`` arrived (monotonic)
        self.state_digest = ''
        self.announced_digest = ''
        self.generation = 0
        self.last_hb: Optional[Tuple[float, float]] = None   # (peer's t1, our receive time t2)
        self.last_req = -math.inf
        self.registered: Set[sync.Registration] = set()
        self.kept_spelling: Dict[str, str] = {}    # caller_id -> URI spelling the master still holds (this generation)
        self.unlisted: Dict[str, str] = {}         # caller_id -> URI of a proxy the master holds without listing it
        self.lost_at = -math.inf
        self.returned_at = -math.inf
        self.their_view: Optional[bool] = None   # whether the peer's last heartbeat said it hears us


class _RememberingTransport(xmlrpc.client.Transport):
    """Keeps the last raw answer to each of the ``remembered`` calls: an answer byte-for-byte like the last
    one is not parsed again (:attr:`unchanged` says so). The master's graph is the same on almost every poll,
    and parsing getSystemState's XML was most of the bridge's cost per poll."""

    remembered = (b'<methodName>getSystemState</methodName>', b'<methodName>getTopicTypes</methodName>')
    # the master is on this host: compressing its answers (xmlrpc does above 1400 B when asked) cost it CPU
    accept_gzip_encoding = False

    def __init__(self) -> None:
        super().__init__()
        self.unchanged = False
        self._key: Optional[bytes] = None
        self._last: Dict[bytes, Tuple[bytes, tuple]] = {}

    def request(self, host, handler, request_body, verbose=False):  # noqa: ANN001 - xmlrpc's signature
        self._key = request_body if any(m in request_body for m in self.remembered) else None
        return super().request(host, handler, request_body, verbose)

    def parse_response(self, response):  # noqa: ANN001 - xmlrpc's signature
        body = response.read()
        if response.getheader('Content-Encoding', '') == 'gzip':
            body = gzip.decompress(body)
        last = self._last.get(self._key) if self._key is not None else None
        self.unchanged = last is not None and last[0] == body
        if self.unchanged:
            return last[1]
        parser, unmarshaller = self.getparser()
        parser.feed(body)
        parser.close()
        result = unmarshaller.close()
        if self._key is not None:
            self._last[self._key] = (body, result)
        return result


class MasterClient:
    """Batched Master API calls (one HTTP request per batch) on behalf of the bridge, over one kept-alive
    connection (the master's XML-RPC server speaks HTTP/1.1): a poll is then one request on an open socket, not
    a TCP set-up on both sides and a new server thread in the master each time. Used from the bridge's main
    thread only. :meth:`reset` after a failure: the next call connects anew."""

    def __init__(self, uri: str, caller_id: str) -> None:
        self.uri = uri
        self.caller_id = caller_id
        self._server: Optional[xmlrpc.client.ServerProxy] = None
        self._transport = _RememberingTransport()

    def _proxy(self) -> xmlrpc.client.ServerProxy:
        if self._server is None:
            self._transport = _RememberingTransport()
            self._server = xmlrpc.client.ServerProxy(self.uri, transport=self._transport)
        return self._server

    def reset(self) -> None:
        if self._server is not None:
            self._server('close')()
            self._server = None

    def system_state(self, previous: Optional[sync.Snapshot], refresh: bool) -> sync.Snapshot:
        """getSystemState; the topic types only when a published topic is new to ``previous`` (or ``refresh``):
        their answer is parsed for nothing on most polls (cnr_benchmarks.bridge_poll). ``previous`` itself
        when the master's answer is the same as last time and no refresh is due."""
        _code, _, state = self._proxy().getSystemState(self.caller_id)
        if previous is not None and not refresh and self._transport.unchanged:
            return previous
        published = {t for t, nodes in state[0] if nodes}
        if previous is None or refresh or not published <= set(previous.types):
            code, _, types = self._proxy().getTopicTypes(self.caller_id)
            types = types if code == 1 else []
        else:
            # every topic still there keeps its type, subscribed-only ones too: dropping those between refreshes
            # flipped their type to '*' in the exported state and back at each refresh (a peer then unregistered
            # and registered the subscriber proxy twice a second)
            current = published | {t for t, nodes in state[1] if nodes}
            types = [(t, ty) for t, ty in previous.types.items() if t in current]
        return sync.Snapshot.from_system_state(state, types)

    def snapshot(self, previous: Optional[sync.Snapshot], refresh_nodes: bool) -> sync.Snapshot:
        snap = self.system_state(previous, refresh_nodes)
        if snap is previous:
            return snap
        names = sorted(snap.node_names())
        services = sorted(snap.services)
        if previous is not None and not refresh_nodes:
            # between refreshes only what is new is looked up: a node not seen before, and a service that is new
            # or has another provider than before (its URI is the new provider's: a cached one kept a migrated
            # service pointing at its old instance until the next refresh)
            snap.nodes = {n: previous.nodes[n] for n in names if n in previous.nodes}
            snap.service_apis = {s: previous.service_apis[s] for s in services
                                 if s in previous.service_apis and previous.services.get(s) == snap.services[s]}
            names = [n for n in names if n not in snap.nodes]
            services = [s for s in services if s not in snap.service_apis]
            if not names and not services:
                return snap
        multi = xmlrpc.client.MultiCall(self._proxy())
        for n in names:
            multi.lookupNode(self.caller_id, n)
        for s in services:
            multi.lookupService(self.caller_id, s)
        results = list(multi()) if names or services else []
        for n, (code, _, uri) in zip(names, results[:len(names)]):
            if code == 1:
                snap.nodes[n] = uri
        for s, (code, _, uri) in zip(services, results[len(names):]):
            if code == 1:
                snap.service_apis[s] = uri
        return snap

    def apply(self, unregister: List[sync.Registration], register: List[sync.Registration],
              in_place: Set[str] = frozenset()) -> List[str]:
        """Unregistrations then registrations in one batch (:func:`sync.batch_order`: the nodes of ``in_place``
        removed and registered again node by node); returns failures."""
        if not unregister and not register:
            return []
        multi = xmlrpc.client.MultiCall(self._proxy())
        # a peer's subscribers and services go first: removing its publishers first made the master notify its
        # subscribers of that, over a link that may be gone (a peer lost), and rosmaster's notifications have
        # no timeout: each one to a host cut off holds one of its notifier threads for minutes, and local
        # nodes' notifications then wait (a failover's new instance was not connected for 135 s)
        calls = sync.batch_order(unregister, register, set(in_place))
        for add, r in calls:
            if r.kind == 'pub':
                if add:
                    multi.registerPublisher(r.caller_id, r.name, r.extra, r.caller_api)
                else:
                    multi.unregisterPublisher(r.caller_id, r.name, r.caller_api)
            elif r.kind == 'sub':
                if add:
                    multi.registerSubscriber(r.caller_id, r.name, r.extra, r.caller_api)
                else:
                    multi.unregisterSubscriber(r.caller_id, r.name, r.caller_api)
            elif add:
                multi.registerService(r.caller_id, r.name, r.extra, r.caller_api)
            else:
                multi.unregisterService(r.caller_id, r.name, r.extra)
        failures = []
        for (_, r), result in zip(calls, multi()):
            if result[0] != 1:
                failures.append(f'{r.kind} {r.name} as {r.caller_id}: {result[1]}')
        return failures

    def node_apis(self, caller_ids: List[str]) -> Dict[str, str]:
        """caller_id -> URI for those the master knows (its own node table: an entry stays while any
        registration lists it, even one that getSystemState no longer shows)."""
        multi = xmlrpc.client.MultiCall(self._proxy())
        for cid in caller_ids:
            multi.lookupNode(self.caller_id, cid)
        return {cid: uri for cid, (code, _, uri) in zip(caller_ids, multi()) if code == 1}

    def register_service(self, caller_id: str, service: str, service_api: str, caller_api: str) -> None:
        self._proxy().registerService(caller_id, service, service_api, caller_api)


class Bridge:
    def __init__(self, cfg: bridge_config.BridgeConfig, master_uri: str, caller_id: str) -> None:
        self.cfg = cfg
        self.master = MasterClient(master_uri, caller_id)
        self.session = protocol.new_session()
        self.seq = 0
        self.guard = protocol.ReplayGuard()
        self.peers: Dict[str, PeerState] = {p.name: PeerState(p, cfg) for p in cfg.peers}
        self.lock = threading.RLock()
        self.wake = threading.Event()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(cfg.listen)
        self.snapshot: Optional[sync.Snapshot] = None
        self.export: dict = {}
        self.export_digest = ''
        self.service_first_seen: Dict[sync.ServiceKey, float] = {}
        # the bridge changed its master since the last poll: plans wait for a poll that shows the change (a plan
        # on an older snapshot takes a proxy just removed for a local node, or a proxy for a hidden local provider)
        self.snapshot_stale = False
        self.shadowed: Dict[str, Tuple[str, str, str]] = {}   # service -> local (node, service_api, node_api)
        self.md5s: Dict[str, str] = {}
        self.local_ages: Dict[str, float] = {}
        self.local_md5s: Dict[str, str] = {}
        self.exported_owned: Optional[Set[str]] = None   # the proxies excluded from the last export
        self.reported: Set[str] = set()
        self.last_node_refresh = -math.inf
        self.master_ok = True
        self.stopped = False
        # rospy runs on_shutdown hooks in its SIGINT handler, i.e. in the main thread, possibly in the
        # middle of reconcile(): the hook only sets ``closing`` (taking a lock there could deadlock), and
        # spin() removes the registrations once its loop has ended. Registrations change only in the main
        # thread (reconcile() in the loop, then shutdown()), so they need no lock of their own.
        self.closing = False
        self.quality_pub = rospy.Publisher('link_quality', LinkQuality, queue_size=10)
        self.poll_requested = False
        rospy.Service('~poll', Empty, self._on_poll_request)

    def _on_poll_request(self, _req) -> EmptyResponse:
        """``~poll``: a node that just registered something has it reach the peers without waiting for the
        next poll (migration_manager's instances call it when they become active)."""
        self.poll_requested = True
        self.wake.set()
        return EmptyResponse()

    # ---------------------------------------------------------------- wire
    def _send(self, peer: PeerState, kind: str, **body) -> None:
        self.seq += 1
        msg = dict(body, kind=kind, seq=self.seq, session=self.session, **{'from': self.cfg.name})
        data = protocol.encode(self.cfg.secret, msg)
        if len(data) > MAX_DATAGRAM:
            self._report(f'state too large for one datagram ({len(data)} B): narrow allow_topics')
            return
        try:
            self.sock.sendto(data, (peer.peer.host, peer.peer.port))
        except OSError as exc:
            rospy.logwarn_throttle(10.0, f'bridge: cannot send to {peer.peer.name} '
                                         f'{peer.peer.host}:{peer.peer.port}: {exc.strerror}')

    def _heartbeat(self, peer: PeerState) -> None:
        echo = None
        if peer.last_hb is not None:
            t1, t2 = peer.last_hb
            echo = [t1, t2, time.time()]
        peer.estimator.on_sent()
        self._send(peer, 'hb', t1=time.time(), echo=echo, digest=self.export_digest, up=peer.alive)

    def receive_loop(self) -> None:
        while not self.stopped:
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM + 1024)
            except OSError:
                return
            now_wall, now = time.time(), time.monotonic()
            try:
                msg = protocol.decode(self.cfg.secret, data)
            except protocol.ProtocolError as exc:
                rospy.logwarn_throttle(5.0, f'bridge: ignored datagram from {addr[0]}:{addr[1]}: {exc}')
                continue
            with self.lock:
                peer = self.peers.get(msg['from'])
                if peer is None:
                    rospy.logwarn_throttle(5.0, f"bridge: ignored datagram from unknown peer "
                                                f"'{msg['from']}' at {addr[0]}:{addr[1]}")
                    continue
                if not self.guard.accept(msg):
                    continue
                self._handle(peer, msg, now, now_wall)

    def _handle(self, peer: PeerState, msg: dict, now: float, now_wall: float) -> None:
        kind = msg['kind']
        if kind == 'hb':
            echo = msg.get('echo')
            if echo:
                peer.estimator.on_heartbeat(now, echo[0], echo[1], echo[2], t4=now_wall)
            else:
                peer.estimator.on_heartbeat(now)
            peer.last_hb = (msg['t1'], now_wall)
            if not peer.alive:
                peer.alive = True
                peer.returned_at = now
                rospy.loginfo(f'bridge: peer {peer.peer.name} is up '
                              f'({peer.peer.host}:{peer.peer.port}); requesting its state')
                self._send(peer, 'req')
                peer.last_req = now
                self._send(peer, 'state', state=self.export, digest=self.export_digest)
            elif msg.get('digest') != peer.state_digest and now - peer.last_req > 0.3:
                self._send(peer, 'req')
                peer.last_req = now
            view = msg.get('up')
            if view is not None:
                if sync.rejoined_without_our_loss(peer.their_view, bool(view), now - peer.returned_at,
                                                  self.cfg.loss_timeout):
                    peer.generation += 1
                    peer.kept_spelling = {}
                    rospy.loginfo(f'bridge: peer {peer.peer.name} lost us and hears us again: reconnecting to its '
                                  f'nodes here too')
                    self.wake.set()
                peer.their_view = bool(view)
        elif kind == 'state':
            if peer.alive:
                peer.state = msg['state']
                peer.state_at = now
                peer.state_digest = msg['digest']
                self.wake.set()
        elif kind == 'req':
            self._send(peer, 'state', state=self.export, digest=self.export_digest)
        elif kind == 'bye':
            rospy.loginfo(f'bridge: peer {peer.peer.name} said goodbye')
            peer.estimator.last_heard = -math.inf
            self.wake.set()

    # ---------------------------------------------------------------- sync
    def _report(self, problem: str) -> None:
        if problem not in self.reported:
            self.reported.add(problem)
            rospy.logwarn(f'bridge: {problem}')

    def _md5(self, msg_type: str) -> Optional[str]:
        if msg_type not in self.md5s:
            try:
                import roslib.message
                cls = roslib.message.get_message_class(msg_type)
                self.md5s[msg_type] = cls._md5sum if cls is not None else ''
            except Exception:  # noqa: BLE001 - an unknown package is not an error here
                self.md5s[msg_type] = ''
        return self.md5s[msg_type] or None

    def owned(self) -> Set[str]:
        return {r.caller_id for p in self.peers.values() for r in p.registered}

    def poll(self, now: float) -> None:
        refresh = now - self.last_node_refresh > 1.0
        previous = self.snapshot
        snap = self.master.snapshot(previous, refresh)
        if refresh:
            self.last_node_refresh = now
        self.snapshot = snap
        self.snapshot_stale = False
        owned = self.owned()
        self._displaced(snap, owned, now)
        self.service_first_seen, ages = sync.service_ages(
            self.service_first_seen, {s: (node, snap.service_apis.get(s, '')) for s, node in snap.services.items()},
            {s: (node, api) for s, (node, api, _) in self.shadowed.items()}, now)
        if snap is previous and owned == self.exported_owned:
            # the master's graph as last time: the exported state too, but for the services' ages
            with self.lock:
                self.export = dict(self.export, srvs={s: [v[0], v[1], round(ages.get(s, 0.0), 3)]
                                                      for s, v in self.export.get('srvs', {}).items()})
            self.local_ages = ages
            return
        self.exported_owned = owned
        md5s = {t: m for t in set(snap.types.values()) for m in [self._md5(t)] if m}
        export = sync.export_state(snap, owned, self.cfg.topics, self.cfg.services, ages, md5s)
        dig = sync.digest(export)
        with self.lock:
            self.export = export
            changed = dig != self.export_digest
            self.export_digest = dig
            if changed:
                for peer in self.peers.values():
                    if peer.alive:
                        self._send(peer, 'state', state=export, digest=dig)
        self.local_ages = ages
        self.local_md5s = md5s

    def _displaced(self, snap: sync.Snapshot, owned: Set[str], now: float) -> None:
        """Service proxies the master no longer lists are counted as not registered (the next reconcile registers
        them again if they are still wanted); a local node listed over one is the newest provider of its service."""
        for peer in self.peers.values():
            gone, taken = sync.displaced(peer.registered, snap, owned)
            if not gone:
                continue
            peer.registered -= gone
            peer.unlisted.update({r.caller_id: r.caller_api for r in gone})
            for service, node in taken.items():
                self.service_first_seen[(service, node, snap.service_apis.get(service, ''))] = now
            rospy.loginfo(f'bridge: {peer.peer.name}: {len(gone)} service proxies no longer served by the master '
                          f'(' + ', '.join(sorted(r.name for r in gone)[:5]) + (', ...' if len(gone) > 5 else '')
                          + (f'; taken over by a local node: {len(taken)}' if taken else '') + ')')

    def _expire(self, now: float) -> None:
        for peer in self.peers.values():
            if peer.alive and not peer.estimator.alive(now):
                peer.alive = False
                peer.lost_at = now
                peer.state = None
                peer.state_digest = ''
                peer.generation += 1
                peer.kept_spelling = {}
                rospy.logwarn(f'bridge: peer {peer.peer.name} lost (nothing heard for '
                              f'{self.cfg.loss_timeout:.1f} s): removing its {len(peer.registered)} '
                              f'registrations')

    def reconcile(self) -> None:
        if not self.closing and not self.snapshot_stale:
            self._reconcile()

    def _reconcile(self) -> None:
        snap = self.snapshot
        if snap is None:
            return
        owned = self.owned()
        for peer in self.peers.values():
            if self.snapshot_stale:
                break   # another peer's changes first show in the next poll
            with self.lock:
                state = sync.aged_state(peer.state, time.monotonic() - peer.state_at) \
                    if peer.alive and peer.state is not None else None
                generation = peer.generation
            if state is None:
                desired: Set[sync.Registration] = set()
            else:
                result = sync.plan(peer.peer.name, state, snap, owned, self.cfg.topics, self.cfg.services,
                                   self.local_ages, self.local_md5s, generation, self.cfg.in_order)
                for problem in result.problems:
                    self._report(problem)
                desired = sync.respell(result.registrations, peer.kept_spelling)
            unregister, register = sync.diff(peer.registered, desired)
            held = {r.caller_id for r in peer.registered}
            arriving = {r.caller_id: r.caller_api for r in register if r.caller_id not in held}
            if arriving:
                kept = sync.kept_spellings(arriving, self.master.node_apis(sorted(arriving)))
                for cid, api in kept.items():
                    rospy.logwarn(f'bridge: {peer.peer.name}: the master still holds {cid} at {api} (a service '
                                  f'of it that a local provider took over, or a registration the bridge no longer '
                                  f'counts as its own): registering it there, not under the other spelling (that '
                                  f'would shut the real node down)')
                if kept:
                    peer.kept_spelling.update(kept)
                    desired = sync.respell(desired, peer.kept_spelling)
                    unregister, register = sync.diff(peer.registered, desired)
            # a proxy's URI spelling changes only after its old registrations are gone from the master: in the
            # same batch where it holds nothing else of it, else after a poll
            keep = peer.registered - set(unregister)
            in_place = sync.respell_in_place(unregister, register, keep, snap, peer.unlisted)
            waiting = {r.caller_id for r in register if sync.must_wait(snap.nodes.get(r.caller_id), r.caller_api)}
            waiting -= in_place
            waiting |= sync.conflicting_identities(register, keep)
            register = [r for r in register if r.caller_id not in waiting]
            in_place &= {r.caller_id for r in register}
            for r in register:
                if r.kind == 'srv':
                    provider = snap.services.get(r.name)
                    if provider is not None and provider not in owned and provider in snap.nodes \
                            and not sync.is_proxy(provider, self.peers):
                        self.shadowed[r.name] = (provider, snap.service_apis.get(r.name, ''),
                                                 snap.nodes[provider])
            if not unregister and not register:
                continue
            started = time.monotonic()
            self.snapshot_stale = True
            self.poll_requested = True
            self.wake.set()
            failures = self.master.apply(unregister, register, in_place)
            for f in failures:
                self._report(f'master refused {f}')
            peer.registered = (peer.registered - set(unregister)) | set(register)
            self._restore_shadowed([r for r in unregister if r.kind == 'srv'])
            rospy.loginfo(f'bridge: {peer.peer.name}: -{len(unregister)} +{len(register)} registrations '
                          f'in {1000 * (time.monotonic() - started):.1f} ms'
                          + (f' ({len(in_place)} nodes at a new URI spelling)' if in_place else ''))

    def _restore_shadowed(self, removed: List[sync.Registration]) -> None:
        """A local provider hidden by a removed proxy serves its service again."""
        snap = self.snapshot
        for r in removed:
            if r.name not in self.shadowed or any(x.kind == 'srv' and x.name == r.name
                                                  for p in self.peers.values() for x in p.registered):
                continue        # a proxy still serves it (e.g. registered again at a new spelling): still hidden
            node, service_api, node_api = self.shadowed.pop(r.name)
            if snap is not None and snap.nodes.get(node) == node_api and service_api:
                try:
                    self.master.register_service(node, r.name, service_api, node_api)
                    rospy.loginfo(f'bridge: {r.name} served by local {node} again')
                except (OSError, xmlrpc.client.Error) as exc:
                    rospy.logwarn(f'bridge: cannot restore {r.name} of {node}: {exc}')

    def publish_quality(self) -> None:
        now = time.monotonic()
        for peer in self.peers.values():
            q = peer.estimator.quality(now)
            msg = LinkQuality()
            msg.header.stamp = rospy.Time.now()
            msg.local_name = self.cfg.name
            msg.peer = peer.peer.name
            msg.alive = peer.alive and peer.estimator.alive(now)
            msg.rtt, msg.rtt_stddev, msg.loss = q.rtt, q.rtt_stddev, q.loss
            msg.clock_offset = q.clock_offset
            msg.heartbeat_rate = self.cfg.heartbeat_rate
            msg.sent, msg.received = q.sent, q.received
            try:
                self.quality_pub.publish(msg)
            except rospy.ROSException:
                if not rospy.is_shutdown():
                    raise

    def spin(self) -> None:
        threading.Thread(target=self.receive_loop, name='bridge-rx', daemon=True).start()
        period = 1.0 / self.cfg.poll_rate
        hb_period = 1.0 / self.cfg.heartbeat_rate
        q_period = 1.0 / self.cfg.quality_rate
        rospy.loginfo(f'bridge {self.cfg.name}: listening on {self.cfg.listen[0]}:{self.cfg.listen[1]}, '
                      f'peers ' + ', '.join(f'{p.name}@{p.host}:{p.port}' for p in self.cfg.peers))
        threading.Thread(target=self.heartbeat_loop, args=(hb_period,), name='bridge-heartbeat', daemon=True).start()
        try:
            self._loop(period, q_period)
        finally:
            self.shutdown()

    def request_stop(self) -> None:
        """rospy.on_shutdown hook: end spin(), which then removes the registrations.

        Only a flag: the hook may run in a signal handler inside any lock of the main thread (even the
        wake event's own); the loop waits at most one poll period, so it sees the flag within that.
        """
        self.closing = True

    def heartbeat_loop(self, period: float) -> None:
        """Heartbeats on a thread of their own, every ``period`` s until the bridge closes. The sync loop waits on
        its master: re-registering a peer's nodes on a busy master (the CPU-capped robot's) can take longer than
        the peer's loss timeout, and heartbeats sent from that loop would then make the peer take us for lost."""
        next_hb = time.monotonic()
        while not rospy.is_shutdown() and not self.closing:
            with self.lock:
                if self.closing:          # after the goodbye, no heartbeat may say we are back
                    return
                for peer in self.peers.values():
                    self._heartbeat(peer)
            next_hb = max(next_hb + period, time.monotonic())
            time.sleep(max(0.0, next_hb - time.monotonic()))

    def _loop(self, period: float, q_period: float) -> None:
        next_poll = next_q = time.monotonic()
        while not rospy.is_shutdown() and not self.closing:
            now = time.monotonic()
            try:
                if now >= next_poll or self.wake.is_set():
                    self.wake.clear()
                    if now >= next_poll or self.poll_requested:
                        self.poll_requested = False
                        next_poll = max(next_poll + period, now)
                        self.poll(now)
                    with self.lock:
                        self._expire(time.monotonic())
                    self.reconcile()
                if not self.master_ok:
                    rospy.loginfo('bridge: master reachable again')
                    self.master_ok = True
            except (OSError, xmlrpc.client.Error) as exc:
                self.master.reset()
                if self.master_ok:
                    rospy.logwarn(f'bridge: local master {self.master.uri} unreachable: {exc}')
                self.master_ok = False
            if now >= next_q:
                next_q = max(next_q + q_period, now)
                self.publish_quality()
            self.wake.wait(max(0.0, min(next_poll, next_q) - time.monotonic()))

    def shutdown(self) -> None:
        """Say goodbye and remove every registration this bridge made (called by spin() as it ends)."""
        self.closing = True
        with self.lock:
            for peer in self.peers.values():
                self._send(peer, 'bye')
        for peer in self.peers.values():
            try:
                self.master.apply(sorted(peer.registered), [])
            except (OSError, xmlrpc.client.Error):
                pass
            peer.registered = set()
        self.stopped = True
        self.sock.close()


@exit_on_config_error
def main() -> None:
    init_node('bridge')
    cfg = bridge_config.parse(private_section('~'))
    # every thread at the control plane's priority (those started later inherit it): re-registering a peer
    # after an outage is one batch of master calls that otherwise queues behind the host's bulk work
    Elevator(cfg.nice, rospy.logwarn).whole_process()
    try:
        bridge = Bridge(cfg, rosgraph.get_master_uri(), rospy.get_name())
    except OSError as exc:
        raise bridge_config.ConfigError(rospy.resolve_name('~'), 'listen',
                                        f'cannot bind {cfg.listen[0]}:{cfg.listen[1]}: {exc.strerror}') from None
    rospy.on_shutdown(bridge.request_stop)
    bridge.spin()
