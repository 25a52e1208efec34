"""``migration_manager``: the robot-side authority that places and moves the managed modules (see the package
README). It grants the leases (the robot keeps working when the cloud is gone), runs each migration
(:class:`migration_manager.core.plan.Migration`) in its own thread, fails a module over to the robot when the
cloud's active instance is cut off, and publishes the events and the placement.
"""
from __future__ import annotations

import itertools
import math
import threading
import time
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import rospy

import cnr_params
from cnr_msgs.msg import AgentHealth, InstanceStatus, MigrationEvent, MigrationLease, MigrationRenew, ModuleState, Placement
from cnr_msgs.srv import AgentCommand, InstanceControl, Migrate, MigrateResponse
from cnr_params.ros import private_section
from cnr_runtime import call_with_timeout, init_node, quiet_at_shutdown
from migration_manager.codes import EVENT_MODE, MODE_WORD, OUTCOME, STEP, TARGET_WORD, health_word
from migration_manager.core import state as state_codec
from migration_manager.core.config import from_section
from cnr_runtime.priority import Elevator
from migration_manager.core.lease import Answer, Grantor, host_of, instance_id
from migration_manager.core.plan import Migration, Step
from migration_manager.instance import lease_topics, topic


class ControlLink:
    """Calls to one instance's control service over a persistent connection (one round trip per call instead of
    a connection set-up each time: the hand-over's freeze and promotion cross the link). A call that fails or
    overruns ``timeout`` closes the connection; the next call opens a new one (e.g. to a restarted instance).
    A stale connection (its instance exited) fails at once and is retried once on a fresh one."""

    def __init__(self, name: str, timeout: float) -> None:
        self.name = name
        self.timeout = timeout
        self.lock = threading.Lock()
        self.proxy: Optional[rospy.ServiceProxy] = None

    def call(self, **request) -> Tuple[bool, object]:
        with self.lock:
            reused = self.proxy is not None
            started = time.monotonic()
            ok, res = self._once(request)
            stale = reused and not ok and not isinstance(res, TimeoutError) and time.monotonic() - started <= 1.0
            return self._once(request) if stale else (ok, res)

    def _once(self, request: dict) -> Tuple[bool, object]:
        if self.proxy is None:
            self.proxy = rospy.ServiceProxy(self.name, InstanceControl, persistent=True)
        ok, res = call_with_timeout(self.proxy, self.timeout, **request)
        if not ok:
            self.proxy.close()
            self.proxy = None
        return ok, res


@dataclass
class Run:
    """A migration being carried out and what the manager tracks beside it."""
    migration: Migration
    agent_pid: int = 0               # the target standby's process (cold), from the agent
    probe_at: float = 0.0            # next probe of the target's control service (STARTING)


class ModuleBook:
    """What the manager knows about one module (guarded by the manager's lock)."""

    def __init__(self, module: str, grantor: Grantor) -> None:
        self.module = module
        self.grantor = grantor
        self.migration: Optional[Migration] = None
        self.replica = state_codec.Replica(module)     # the current holder's newest replicas (its own lock:
        self.replica_lock = threading.Lock()            # decoding a whole state is not done under the manager's)
        self.status: Dict[str, InstanceStatus] = {}    # host -> newest status
        self.keyframe_asked = -1e9                      # monotonic time of the last keyframe request
        self.first_grant: Dict[int, float] = {}        # term -> monotonic time of its first granted renewal

    def host(self) -> str:
        return host_of(self.grantor.holder) if self.grantor.holder else ''

    def replicated(self, instance: str) -> Optional[bytes]:
        """The newest replica of ``instance`` as a patch that changes nothing (a few bytes: a target that holds
        it resolves it; one that does not is sent the whole state, :meth:`whole`), or None without one."""
        with self.replica_lock:
            seq = self.replica.seq_of(instance)
        return state_codec.encode_patch(self.module, seq, {'{': {}}) if seq else None

    def whole(self, instance: str, data: bytes) -> Optional[bytes]:
        """``data`` (a state or a patch to a replica of ``instance``) as the whole state, or None if the patch's
        base is not held here either."""
        try:
            with self.replica_lock:
                state = self.replica.resolve(instance, data)
        except state_codec.StateError:
            return None
        return state_codec.encode(self.module, state)


class Manager:
    def __init__(self) -> None:
        p = private_section('~')
        self.cfg = cfg = from_section(p.section('migration'))
        Elevator(cfg.control_nice, rospy.logwarn).whole_process()
        placement = p.raw('placement')
        if not isinstance(placement, dict):
            raise p.error('placement', f'must map modules to hosts, got {placement!r}')
        self.initial: Dict[str, str] = {}
        for module in cfg.modules:
            host = str(placement.get(module, cfg.authority))
            if host not in cfg.hosts:
                raise p.error('placement', f'{module}: host must be one of {", ".join(cfg.hosts)}, got {host!r}')
            self.initial[module] = host
        self.lock = threading.RLock()
        self.ids = itertools.count(1)
        self.books: Dict[str, ModuleBook] = {m: ModuleBook(m, cfg.lease.grantor(m, cfg.authority))
                                             for m in cfg.modules}
        # each module's answers over every path (lease_topics): the first also carries the announcements
        self.lease_pubs = {m: [rospy.Publisher(t, MigrationLease, queue_size=50)
                               for t in lease_topics(m, 'lease', cfg.lease.paths)] for m in cfg.modules}
        self.event_pub = rospy.Publisher('~events', MigrationEvent, queue_size=100)
        self.placement_pub = rospy.Publisher('~placement', Placement, queue_size=5, latch=True)
        self.control = {(m, h): ControlLink(topic(m, f'{h}/control'), cfg.control_call)
                        for m in cfg.modules for h in cfg.hosts}
        self.agents = {h: rospy.ServiceProxy(f'/migration/agents/{h}/command', AgentCommand) for h in cfg.hosts}
        for m in cfg.modules:
            for t in lease_topics(m, 'renew', cfg.lease.paths):
                # no Nagle: a request sent behind a lost one is not held back until that one is acknowledged
                rospy.Subscriber(t, MigrationRenew, self._on_renew, queue_size=50, tcp_nodelay=True)
            rospy.Subscriber(topic(m, 'state'), ModuleState, self._on_state, queue_size=2)
            for h in cfg.hosts:
                rospy.Subscriber(topic(m, f'{h}/status'), InstanceStatus, self._on_status, queue_size=10)
        self.health: Dict[str, Dict[str, Tuple[int, int, int]]] = {}  # host -> module -> (state, exit code, pid)
        for h in cfg.hosts:
            rospy.Subscriber(f'/migration/agents/{h}/health', AgentHealth, self._on_health, queue_size=5)
        rospy.Service('~migrate', Migrate, self._on_migrate)

    # ------------------------------------------------------------------ lease protocol
    def _answer(self, a: Answer, instance: str = '') -> None:
        """Publish an answer to ``instance``'s request over each of its paths (an instance on the authority's
        host has one), or an announcement (no instance) over the first."""
        msg = MigrationLease(module=a.module, term=a.term, holder=a.holder, nonce=a.nonce, granted=a.granted,
                             duration=a.duration)
        paths = self.cfg.lease.paths_on(host_of(instance), self.cfg.authority) if instance else 1
        for pub in self.lease_pubs[a.module][:paths]:
            pub.publish(msg)

    @quiet_at_shutdown
    def _on_renew(self, msg: MigrationRenew) -> None:
        book = self.books.get(msg.module)
        if book is None:
            return
        now = time.monotonic()
        with self.lock:
            if msg.term == 0:                 # a standby's request: kept for a promotion's pre-grant
                book.grantor.standby_request(msg.instance, msg.nonce, now)
                return
            if not book.grantor.first_receipt(msg.instance, msg.nonce):
                return                        # a copy that came over another path: answered already
            a = book.grantor.request(msg.instance, msg.term, msg.nonce, now)
            if a.granted and msg.term not in book.first_grant:
                book.first_grant[msg.term] = now
        self._answer(a, msg.instance)

    def _on_state(self, msg: ModuleState) -> None:
        book = self.books.get(msg.module)
        if book is None:
            return
        with self.lock:
            if msg.instance != book.grantor.holder or msg.term != book.grantor.term:
                return
        try:
            with book.replica_lock:
                held = book.replica.take(msg.instance, msg.seq, msg.base_seq, bytes(msg.data))
        except state_codec.StateError as exc:
            rospy.logwarn(f'{msg.module}: replica {msg.seq} of {msg.instance} ignored: {exc}')
            return
        if not held:
            self._ask_keyframe(book, msg.instance)
        with self.lock:
            if book.migration is not None:
                book.migration.replicated = book.replicated(msg.instance) or book.migration.replicated

    def _ask_keyframe(self, book: ModuleBook, instance: str) -> None:
        """A patch to a replica the manager does not hold (it started after the last whole one): ask for a whole
        state (at most once per ``timeouts.control_call``; never waited on)."""
        now = time.monotonic()
        if now - book.keyframe_asked < self.cfg.control_call:
            return
        book.keyframe_asked = now
        link = self.control.get((book.module, host_of(instance)))
        if link is not None:
            threading.Thread(target=link.call, kwargs=dict(command='keyframe'), name='keyframe-request',
                             daemon=True).start()

    def _on_status(self, msg: InstanceStatus) -> None:
        book = self.books.get(msg.module)
        if book is not None:
            with self.lock:
                book.status[host_of(msg.instance)] = msg

    def _on_health(self, msg: AgentHealth) -> None:
        with self.lock:
            self.health[msg.host] = {m: (st, code, pid) for m, st, code, pid
                                     in zip(msg.modules, msg.states, msg.exit_codes, msg.pids)}

    # ------------------------------------------------------------------ calls with timeouts
    def _call(self, proxy, *args) -> Tuple[bool, object]:
        return call_with_timeout(proxy, self.cfg.control_call, *args)

    def _instance_up(self, module: str, host: str) -> bool:
        """The instance answers and is ready (a standby's inputs are connected). ``ping``, not ``state``: a
        store standby would encode its whole store for every probe, on the capped robot."""
        ok, res = self.control[(module, host)].call(command='ping')
        return ok and res.ok and res.message != 'not ready'

    def _holds_replica(self, book: ModuleBook, host: str, source: str) -> bool:
        """The standby on ``host`` reports that it holds a replica of the instance active on ``source``."""
        st = book.status.get(host)
        return bool(source) and st is not None and st.replica_of == instance_id(book.module, source) \
            and st.replica_seq > 0

    # ------------------------------------------------------------------ migrations
    def _event(self, mid: int, m: Migration, message: str, at: Optional[float] = None) -> None:
        """Publish and log one event; ``at`` (monotonic) is when it happened (the stamp; default now): events
        are published after the actions that made them, which may cross the link."""
        ev = MigrationEvent(id=mid, module=m.module, source=m.source, target=m.target, mode=EVENT_MODE[m.mode],
                            step=STEP[m.step], message=message, term=m.term,
                            downtime=m.downtime if m.step is Step.DONE and m.downtime is not None else math.nan)
        ev.header.stamp = rospy.Time.from_sec(time.time() - (0.0 if at is None else time.monotonic() - at))
        try:
            self.event_pub.publish(ev)
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise
        since = f' [+{1000 * (at - m.started):.0f} ms]' if at is not None else ''
        rospy.loginfo(f'migration {mid} {m.module} {m.source or "-"}->{m.target} ({m.mode}){since}: {message}')

    def run_migration(self, module: str, target: str, mode: str, failover: bool = False) -> Tuple[int, Migration]:
        """Carry out one migration to its end (blocking); returns its number and its final state."""
        book = self.books[module]
        mid = next(self.ids)
        now = time.monotonic()
        with self.lock:
            if book.migration is not None:
                raise ValueError(f'{module} is already migrating ({book.migration.source}->{book.migration.target})')
            m = Migration(module, book.host(), target, mode, self.cfg.timeouts, book.grantor, now,
                          failover=failover)
            m.replicated = book.replicated(book.grantor.holder)
            book.migration = m
        self._publish_placement()
        seen = 0
        run = Run(m)
        try:
            # a failover takes a standby its status calls ready at once: a ping first cost up to 2 s on the loaded
            # robot, and the cut-off holder's renewals, queued in the link, were granted meanwhile (each one
            # put the promotion off by a lease); a standby that is gone fails the promotion, which is rolled back
            ready = self._standby_running(book, target) if failover else \
                self._instance_up(module, target) and self._standby(book, target)
            with self.lock:
                actions = m.begin(time.monotonic(), ready, self._holds_replica(book, target, m.source))
            while True:
                while actions:                       # an action's outcome may call for more actions
                    verb, host, detail = actions.pop(0)
                    actions += self._do(run, verb, host, detail)
                with self.lock:
                    for ev in m.events[seen:]:
                        self._event(mid, m, ev.message, ev.at)
                    seen = len(m.events)
                    if m.finished:
                        break
                    actions = self._poll(book, run)
                if not actions:
                    time.sleep(0.01)
        finally:
            with self.lock:
                book.migration = None
            self._publish_placement()
        return mid, m

    def _standby(self, book: ModuleBook, host: str) -> bool:
        st = book.status.get(host)
        return st is not None and st.role == InstanceStatus.STANDBY and st.ready

    def _standby_running(self, book: ModuleBook, host: str) -> bool:
        """A ready standby by its status whose process its agent reports running (no call: the status and the
        health are the last published)."""
        st = book.status.get(host)
        state, _, pid = self.health.get(host, {}).get(book.module, (AgentHealth.STOPPED, 0, 0))
        return self._standby(book, host) and state == AgentHealth.RUNNING and pid == st.pid

    def _poll(self, book: ModuleBook, run: Run) -> List:
        """Events from the world, then deadlines (caller holds the lock)."""
        m = run.migration
        now = time.monotonic()
        if m.step is Step.STARTING and run.probe_at <= now:
            run.probe_at = now + 0.2
            self.lock.release()
            try:
                up = self._instance_up(m.module, m.target)
            finally:
                self.lock.acquire()
            if up:
                return m.target_ready(time.monotonic(), self._holds_replica(book, m.target, m.source))
        if m.step is Step.STARTING:
            state, code, pid = self.health.get(m.target, {}).get(m.module, (AgentHealth.STOPPED, 0, 0))
            if state == AgentHealth.EXITED and pid and pid == run.agent_pid:
                return m.target_failed(now, f'the standby on {m.target} {health_word(state, code)} at start')
        if m.step is Step.PROMOTING and m.term in book.first_grant:
            return m.target_active(book.first_grant[m.term], m.term)
        st = book.status.get(m.target)
        if m.step in (Step.PROMOTING,) and st is not None and st.role == InstanceStatus.SUPERSEDED \
                and st.term == m.term:
            return m.target_failed(now, 'the target was superseded')
        return m.tick(now)

    def _do(self, run: Run, verb: str, host: str, detail) -> List:
        """One action of a migration (no lock held: calls may take up to control_call); returns the actions its
        outcome calls for."""
        m = run.migration
        if verb == 'start_standby':
            with self.lock:
                st = self.books[m.module].status.get(host)
                dormant = st is not None and st.role == InstanceStatus.DORMANT
            if dormant:              # a retired instance asleep there: woken, it is a standby in a moment
                ok, res = self.control[(m.module, host)].call(command='wake')
                if ok and res.ok:
                    run.agent_pid = st.pid
                    with self.lock:
                        m.woken = True
                    rospy.loginfo(f'{m.module}: woke the dormant instance on {host} (pid {st.pid}) instead of '
                                  f'starting a clone')
                    return []
                rospy.logwarn(f'{m.module}: waking the dormant instance on {host} failed '
                              f'({res if not ok else res.message}): starting a new one')
                self._call(self.agents[host], 'stop', m.module)
            ok, res = self._call(self.agents[host], 'start', m.module)
            if ok and res.ok:
                run.agent_pid = res.pid
                return []
            with self.lock:
                return m.target_failed(time.monotonic(), f'agent on {host}: {res if not ok else res.message}')
        if verb == 'freeze':
            book = self.books[m.module]
            with book.replica_lock:          # the final state comes as a patch to the replica held here
                base = book.replica.seq_of(instance_id(m.module, host))
            ok, res = self.control[(m.module, host)].call(command='freeze', term=detail, base_seq=base)
            with self.lock:
                if ok and res.ok:
                    return m.frozen(time.monotonic(), bytes(res.state))
                return m.source_unreachable(time.monotonic())
        if verb == 'promote':
            term, state = detail
            book = self.books[m.module]
            with self.lock:                   # the lease for the target's newest standby request, granted now
                nonce, duration = book.grantor.pregrant(instance_id(m.module, host), time.monotonic())
            base = instance_id(m.module, m.source)         # whose replica a patched state refers to
            link = self.control[(m.module, host)]
            ok, res = link.call(command='promote', term=term, state=state or b'', base_instance=base,
                                nonce=nonce, duration=duration)
            if ok and not res.ok and res.message.startswith(state_codec.BASE_MISSING):
                whole = book.whole(base, state)              # the target lacks the patch's base: the whole state
                rospy.loginfo(f'{m.module}: {host} does not hold the replica the state is a patch to: sending the '
                              f'whole state ({len(whole) if whole else 0} bytes)')
                if whole is not None:
                    ok, res = link.call(command='promote', term=term, state=whole, base_instance=base, nonce=nonce,
                                        duration=duration)
            if ok and res.ok:
                if res.active:                # active before it answered
                    with self.lock:
                        book.first_grant.setdefault(term, time.monotonic())
                return []
            with self.lock:
                if host == m.target:
                    return m.target_failed(time.monotonic(), f'promotion refused: {res if not ok else res.message}')
            rospy.logerr(f'{m.module}: reinstating {host} failed: {res if not ok else res.message}')
            return []
        if verb == 'retire':
            cold = detail == 'cold' or m.module not in self.cfg.hot_standby
            if m.failover and not cold:
                # the source is cut off: it steps down by itself once it hears the newer term, and its agent starts
                # it again as a standby, which is what a hot module keeps there; calls to it now would only hold
                # the module "migrating" until they time out
                return []
            if cold and host in self.cfg.dormant.get(m.module, ()):
                ok, res = self.control[(m.module, host)].call(command='sleep')
                if ok and res.ok:
                    rospy.loginfo(f'{m.module}: the retired instance on {host} sleeps (dormant)')
                else:      # it cannot sleep: stopped as any retired cold instance
                    rospy.logwarn(f'{m.module}: the retired instance on {host} did not go dormant '
                                  f'({res if not ok else res.message}): stopping it')
                    self._call(self.agents[host], 'stop', m.module)
            elif cold:
                self._call(self.agents[host], 'stop', m.module)
            else:                     # hot: the old instance makes way for a fresh standby there
                self._call(self.agents[host], 'stop', m.module)
                self._call(self.agents[host], 'start', m.module)
        elif verb == 'stop':
            self._call(self.agents[host], 'stop', m.module)
        return []

    @quiet_at_shutdown
    def _on_migrate(self, req) -> MigrateResponse:
        started = time.monotonic()
        refused = MigrateResponse.REFUSED
        if req.module not in self.books:
            return MigrateResponse(ok=False, outcome=refused, downtime=math.nan,
                                   message=f'{req.module!r} is not managed ({", ".join(self.books)})')
        target = TARGET_WORD.get(req.target, '')
        if target not in self.cfg.hosts:
            return MigrateResponse(ok=False, outcome=refused, downtime=math.nan,
                                   message=f'target must be one of {", ".join(self.cfg.hosts)}')
        mode = MODE_WORD.get(req.mode, f'code {req.mode}') or ('hot' if req.module in self.cfg.hot_standby else 'cold')
        try:
            mid, m = self.run_migration(req.module, target, mode)
        except ValueError as exc:
            return MigrateResponse(ok=False, outcome=refused, message=str(exc), downtime=math.nan)
        outcome = OUTCOME[m.step.value]
        message = m.events[-1].message if m.events else ''
        if m.woken:
            message += f'; woke the dormant instance on {m.target}'
        return MigrateResponse(ok=m.step is Step.DONE, outcome=outcome, id=mid, term=m.term, message=message,
                               downtime=m.downtime if m.downtime is not None else math.nan,
                               duration=time.monotonic() - started)

    # ------------------------------------------------------------------ placement, failover, start-up
    def _publish_placement(self) -> None:
        msg = Placement()
        with self.lock:
            for module, book in self.books.items():
                msg.modules.append(module)
                msg.hosts.append(book.host())
                msg.terms.append(book.grantor.term)
                msg.migrating.append(book.migration is not None)
        msg.header.stamp = rospy.Time.from_sec(time.time())
        try:
            self.placement_pub.publish(msg)
        except rospy.ROSException:
            if not rospy.core.is_shutdown_requested():
                raise

    def start_modules(self) -> None:
        """The initial placement; a module the cloud cannot take (link down) starts on the robot."""
        def agent_up(module: str, host: str) -> bool:
            try:                     # the agent there may still be starting (it resolves its launches first)
                self.agents[host].wait_for_service(self.cfg.timeouts.start)
                return True
            except rospy.ROSException:
                rospy.logwarn(f'{module}: the agent on {host} is not there after {self.cfg.timeouts.start:g} s')
                return False

        def start(module: str, host: str) -> None:
            agent_up(module, host)
            _, m = self.run_migration(module, host, 'cold')
            if m.step is not Step.DONE and host != self.cfg.authority:
                rospy.logwarn(f'{module}: cannot start on {host} ({m.error}): starting it on {self.cfg.authority}')
                _, m = self.run_migration(module, self.cfg.authority, 'cold')
            while m.step is not Step.DONE and not rospy.core.is_shutdown_requested():
                # the robot's own agent may still be starting: keep trying there (it never depends on the cloud)
                rospy.logwarn_throttle(10.0, f'{module}: not started on {self.cfg.authority} yet ({m.error}); '
                                             f'trying again')
                time.sleep(1.0)
                _, m = self.run_migration(module, self.cfg.authority, 'cold')
            for other in self.cfg.hosts:
                # the warm standby on the other host: its agent may be later than the first start's (a store
                # started on the cloud before the robot's agent was up had no standby on the robot, and its
                # failover had to start one under the robot's CPU cap)
                if module in self.cfg.hot_standby and other != self.books[module].host() and agent_up(module, other):
                    ok, res = self._call(self.agents[other], 'start', module)
                    if not ok or not res.ok:
                        rospy.logwarn(f'{module}: no warm standby on {other}: '
                                      f'{res if not ok else res.message}')
                elif other in self.cfg.dormant.get(module, ()) and other != self.books[module].host() \
                        and agent_up(module, other):
                    self._start_asleep(module, other)
        threads = [threading.Thread(target=start, args=item, daemon=True) for item in self.initial.items()]
        for t in threads:
            t.start()

    def _start_asleep(self, module: str, host: str) -> None:
        """A dormant instance of ``module`` on ``host`` from the start: started as a standby, put to sleep once it
        is ready. A failover there then wakes it instead of starting a clone (move_base under the robot's CPU cap:
        about 10 s more)."""
        ok, res = self._call(self.agents[host], 'start', module)
        if not ok or not res.ok:
            rospy.logwarn(f'{module}: no dormant instance on {host}: {res if not ok else res.message}')
            return
        deadline = time.monotonic() + self.cfg.timeouts.start
        while not self._instance_up(module, host):
            if time.monotonic() > deadline or rospy.core.is_shutdown_requested():
                rospy.logwarn(f'{module}: the instance started on {host} to sleep there was not ready within '
                              f'{self.cfg.timeouts.start:g} s: left as it is')
                return
            time.sleep(0.5)
        with self.lock:
            busy = self.books[module].migration is not None
        if busy:                  # a migration (a failover) may be using it: it is that migration's now
            return
        ok, res = self.control[(module, host)].call(command='sleep')
        if ok and res.ok:
            rospy.loginfo(f'{module}: an instance on {host} sleeps (dormant) for a failover or migration there')
        else:
            rospy.logwarn(f'{module}: the instance on {host} did not go to sleep: {res if not ok else res.message}')

    def spin(self) -> None:
        next_announce = time.monotonic()
        while not rospy.core.is_shutdown_requested():
            now = time.monotonic()
            for book in self.books.values():
                with self.lock:
                    holder_host = book.host()
                    idle = book.migration is None and holder_host and now > book.grantor.valid_until
                    lapsed = (idle and holder_host != self.cfg.authority and book.grantor.term in book.first_grant)
                    # the authority's own instance lost its lease (it exited: its agent restarts it as a standby;
                    # or an earlier recovery failed): that standby takes over, nothing else would
                    lost_here = (idle and holder_host == self.cfg.authority
                                 and self._standby(book, self.cfg.authority))
                if lapsed and self.cfg.failover:
                    rospy.logwarn(f'{book.module}: the active instance on {holder_host} lost its lease (cut off?): '
                                  f'failing over to {self.cfg.authority}')
                    mode = 'hot' if book.module in self.cfg.hot_standby else 'cold'
                    threading.Thread(target=self._failover, args=(book.module, mode), daemon=True).start()
                elif lost_here and self.cfg.failover:
                    rospy.logwarn(f'{book.module}: the active instance on {holder_host} lost its lease and a '
                                  f'standby is ready there (restarted by its agent): promoting it')
                    threading.Thread(target=self._failover, args=(book.module, 'hot'), daemon=True).start()
            if now >= next_announce:
                next_announce = now + self.cfg.status_period
                for book in self.books.values():
                    with self.lock:
                        a = book.grantor.announcement()
                    try:
                        self._answer(a)
                    except rospy.ROSException:
                        if rospy.core.is_shutdown_requested():
                            return
                        raise
                self._publish_placement()
            time.sleep(0.02)

    def _failover(self, module: str, mode: str) -> None:
        try:
            self.run_migration(module, self.cfg.authority, mode, failover=True)
        except ValueError:
            pass                      # a migration started meanwhile


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('migration_manager')
    manager = Manager()
    if private_section('~').boolean('start_modules'):
        manager.start_modules()
    manager.spin()
