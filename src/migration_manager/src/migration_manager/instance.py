"""The module side of migrations: what a movable node (mfg, local_mapcell_manager, global_goal_manager,
move_base) uses to be started as a standby, promoted, frozen and fenced by the migration manager.

A node creates one :class:`ManagedInstance` with its :class:`Hooks` before its first subscriber, or calls
:func:`prepare_process` before it (see :func:`cnr_runtime.distinct_callerid`). When the node runs without a migration
manager (``~migration/role`` empty or absent: every single-master and fixed-placement run) the instance is
*unmanaged*: always active, no extra topics. Managed, it follows the lease protocol of
:mod:`migration_manager.core.lease`:

- standby: inputs connected, outputs closed (``active`` is False), no lease; it sends standby requests (term
  0) every ``renew_period``, which the manager does not answer but may grant with a promotion;
- promote(term, state, nonce, duration): ``set_state`` (if a state came); active at once (``on_active`` before
  the order is answered) if the order grants one of its standby requests, else from the first granted renewal;
  renewal requests every ``renew_period``, active while they keep being granted;
- a lapse (no grant for ``duration``, e.g. cut off): outputs closed until renewals are granted again;
- superseded (a newer term or another holder announced) or frozen: outputs closed for good (``on_frozen``);
  a superseded instance shuts its node down (its agent starts a fresh standby if one is wanted here);
- dormant (``sleep``, a frozen instance the manager keeps on its host instead of stopping it, for modules that
  implement ``on_sleep``): inputs closed too, no requests, nothing but its status and its copy of the active
  instance's replicas (so that, woken, it is promoted with a patch at once); ``wake`` makes it a standby
  again (``on_wake``), which the next migration to this host promotes instead of starting a clone;
- the active instance publishes its state every ``replicate_period`` on ``/migration/<module>/state``
  (``replicate_period_authority`` on the manager's host): a whole state every ``replicate_keyframe_every``
  replicas, patches to the one before between them (:mod:`migration_manager.core.state`); a standby keeps the
  newest replicas and asks the active instance for a whole state (``keyframe``) when it holds none, so that a
  promotion can bring a patch to one of them instead of the whole state; a freeze answers with a patch to the
  replica the manager says it holds. A node that implements ``prepare_state`` is given the newest replica as
  it arrives (in a thread of its own, at its own priority), to do a promotion's bulk ahead; its status then
  names the newest replica prepared, not only received (a migration here waits for one: ``timeouts.replica``).

Topics and services (``<m>`` the module, ``<h>`` this host): ``/migration/<m>/renew`` (out),
``/migration/<m>/lease`` (in), ``/migration/<m>/state`` (out, while active), ``/migration/<m>/<h>/status``
(out, latched), service ``/migration/<m>/<h>/control`` (cnr_msgs/InstanceControl).
"""
from __future__ import annotations

import os
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

import rospy

from cnr_msgs.msg import InstanceStatus, MigrationLease, MigrationRenew, ModuleState
from cnr_msgs.srv import InstanceControl, InstanceControlResponse
from cnr_params.ros import private_section
from cnr_runtime import call_with_timeout, distinct_callerid, quiet_at_shutdown
from std_srvs.srv import Empty
from migration_manager.codes import ROLE
from migration_manager.core import state as state_codec
from migration_manager.core.config import MigrationConfig, from_section
from migration_manager.core.lease import INSTANCE_HEADER, Answer, Holder, host_of, instance_id
from cnr_runtime.priority import Elevator


class Hooks:
    """What the node provides. ``get_state``/``set_state`` are the module's documented state interface."""

    def get_state(self) -> Dict[str, Any]:
        """A JSON-able snapshot, built afresh: the replicas are patches to the previous snapshot, so it must not
        share anything the node changes later."""
        raise NotImplementedError

    def set_state(self, state: Dict[str, Any]) -> None:
        raise NotImplementedError

    def prepare_state(self, state: Dict[str, Any]) -> None:
        """Optional: a standby is given the active instance's newest replica (whole; the newest only, when
        several arrived meanwhile), so that ``set_state`` at a promotion has less to do. Called in a thread of
        its own while a standby; one call may still run when the promotion's ``set_state`` begins (the node
        serialises the two). Must not change ``state``. ValueError: logged (the replica does not fit)."""

    def standby_ready(self) -> bool:
        """A standby can be promoted without losing input (e.g. its input subscriptions are connected)."""
        return True

    def on_active(self) -> None:
        """Outputs open (first activation, or again after a lapse)."""

    def on_frozen(self) -> None:
        """Outputs closed for good (frozen for a migration, or superseded). Runs before the freeze is answered:
        keep it quick (the hand-over waits for it); the outputs are already gated by ``active``."""

    def after_frozen(self) -> None:
        """Slow clean-up after a freeze (e.g. unregistering services with the master), in a thread of its own
        once the freeze was answered. A promotion that follows (a rolled-back migration) may run meanwhile."""

    def on_sleep(self) -> None:
        """A frozen instance goes dormant: close the inputs too (no CPU, no traffic) but keep the process and
        what it built, so that :meth:`on_wake` is quick. NotImplementedError: the module cannot (the manager
        then stops the instance)."""
        raise NotImplementedError

    def on_wake(self) -> None:
        """A dormant instance becomes a standby again: inputs open, own state reset (a promotion gives it the
        handed-over one)."""
        raise NotImplementedError


class Retiring:
    """A frozen instance's services and publishers: unregistered with the master once the freeze was answered
    (``Hooks.after_frozen`` calls :meth:`close`), or by a promotion that follows before that (a rolled-back
    migration registers the same names again: it calls :meth:`close` first, which waits for one in progress)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.pending: list = []

    def add(self, *handles) -> None:
        with self.lock:
            self.pending += [h for h in handles if h is not None]

    def close(self) -> None:
        with self.lock:
            pending, self.pending = self.pending, []
            for h in pending:
                if isinstance(h, rospy.Publisher):
                    h.unregister()
                else:
                    h.shutdown('frozen for a migration')


def topic(module: str, leaf: str) -> str:
    return f'/migration/{module}/{leaf}'


def lease_topics(module: str, leaf: str, paths: int) -> List[str]:
    """The topics of ``paths`` connections for one kind of lease traffic (``renew`` or ``lease``): the first is
    ``/migration/<module>/<leaf>``, the k-th ``.../<leaf><k>``. Each is a TCP connection of its own, so a packet
    lost on one stalls only that one until its retransmission."""
    return [topic(module, leaf if k == 1 else f'{leaf}{k}') for k in range(1, paths + 1)]


def prepare_process(namespace: str = '~migration') -> bool:
    """For a node that creates subscribers before its :class:`ManagedInstance`: if it runs managed, give its
    subscriptions their per-host caller id now (see :func:`cnr_runtime.distinct_callerid`). Returns whether it
    runs managed. Idempotent; :class:`ManagedInstance` calls it too."""
    role = rospy.get_param(f'{namespace}/role', '')
    if role:
        # (an agent-started instance has it from before init_node: modules.launch sets CNR_CALLERID_SUFFIX)
        distinct_callerid(str(rospy.get_param(f'{namespace}/host', '')))
    return bool(role)


class ManagedInstance:
    def __init__(self, module: str, hooks: Hooks, namespace: str = '~migration') -> None:
        self.module = module
        self.hooks = hooks
        section = private_section(namespace)
        self.role_param = section.string('role', '') if 'role' in section else ''
        self.managed = bool(self.role_param)
        if self.managed:
            distinct_callerid(section.string('host'))
        self.lock = threading.RLock()
        self.frozen = False
        self.dormant = False               # asleep after a freeze (``sleep``), until ``wake``
        self.frozen_wall = 0.0             # wall time the outputs were closed for good (the status's stamp then)
        self.was_active = False
        self.activation = threading.Lock()     # on_active / lapse transitions: one thread at a time
        self.wake = threading.Event()          # the loop's sleep, cut short after a promotion
        self.message = ''
        if not self.managed:
            return
        if self.role_param != 'standby':
            raise section.error('role', f'must be standby (or empty: unmanaged), got {self.role_param!r}')
        self.host = section.string('host')
        self.cfg: MigrationConfig = from_section(section)
        if self.host not in self.cfg.hosts:
            raise section.error('host', f'must be one of {", ".join(self.cfg.hosts)}, got {self.host!r}')
        self.id = instance_id(module, self.host)
        self.holder = Holder(module, self.id)
        # on the manager's host a freeze never crosses the link: replicas there only cover a crash or a hang
        self.replicate_period = (self.cfg.replicate_period_authority if self.host == self.cfg.authority
                                 else self.cfg.replicate_period)
        self.elevator = Elevator(self.cfg.control_nice, rospy.logwarn)   # the protocol's threads (cnr_runtime.priority)
        self.replicator = state_codec.Replicator(module, self.cfg.replicate_keyframe_every)
        self.replica = state_codec.Replica(module)     # the active instance's newest replicas (as a standby)
        self.replica_lock = threading.Lock()
        self.keyframe_asked = -1e9             # monotonic time of this standby's last keyframe request
        self.keyframe_missing = ('', 0)        # (instance, replica seq) when a patch without its base last made it ask
        # across the link: a short lease, renewed often, over several connections (config/migration.yaml lease)
        self.renew_period = self.cfg.lease.renew_period_on(self.host, self.cfg.authority)
        paths = self.cfg.lease.paths_on(self.host, self.cfg.authority)
        self.renew_pubs = [rospy.Publisher(t, MigrationRenew, queue_size=10)
                           for t in lease_topics(module, 'renew', paths)]
        self.state_pub = rospy.Publisher(topic(module, 'state'), ModuleState, queue_size=2)
        self.status_pub = rospy.Publisher(topic(module, f'{self.host}/status'), InstanceStatus, queue_size=5,
                                          latch=True)
        for t in lease_topics(module, 'lease', paths):
            # no Nagle: an answer sent behind a lost one is not held back until that one is acknowledged
            rospy.Subscriber(t, MigrationLease, self._on_lease, queue_size=20, tcp_nodelay=True)
        self.replica_sub: Optional[rospy.Subscriber] = None
        # the newest replica not given to prepare_state yet: (instance, seq, whole state)
        self.to_prepare: Optional[Tuple[str, int, Dict[str, Any]]] = None
        self.prepare_wake = threading.Condition()
        self.prepares = type(hooks).prepare_state is not Hooks.prepare_state
        self.prepared = ('', 0)        # (instance, seq) of the newest replica prepare_state took in (replica_lock)
        if self.prepares:
            # created before the elevated protocol threads: it runs at the module's own priority
            threading.Thread(target=self._prepare_loop, name='migration-prepare', daemon=True).start()
        self._follow_replicas(True)
        rospy.Service(topic(module, f'{self.host}/control'), InstanceControl, self._on_control)
        threading.Thread(target=self._loop, name='migration-instance', daemon=True).start()
        threading.Thread(target=self._renew_loop, name='migration-renew', daemon=True).start()

    # ------------------------------------------------------------------ for the node
    @property
    def active(self) -> bool:
        """May the node produce output now?"""
        if not self.managed:
            return True
        with self.lock:
            return not self.frozen and self.holder.active(time.monotonic())

    def headers(self) -> Optional[Dict[str, str]]:
        """Connection headers for the node's output publishers (consumers can tell the instance apart)."""
        return {INSTANCE_HEADER: self.id} if self.managed else None

    def publisher(self, name: str, data_class, **kwargs) -> rospy.Publisher:
        return rospy.Publisher(name, data_class, headers=self.headers(), **kwargs)

    # ------------------------------------------------------------------ protocol
    def _role(self) -> str:
        if self.dormant:
            return 'dormant'
        if self.frozen:
            return 'frozen'
        if self.holder.superseded:
            return 'superseded'
        if self.holder.term == 0:
            return 'standby'
        return 'active' if self.holder.active(time.monotonic()) else 'promoted'

    def _status(self) -> None:
        with self.lock:
            role = self._role()
        ready = role != 'dormant' and (role != 'standby' or bool(self.hooks.standby_ready()))
        # a node that prepares replicas names the newest prepared (package README, "Waiting for a replica")
        with self.replica_lock:
            replica_of, replica_seq = self.prepared if self.prepares else (self.replica.instance, self.replica.seq)
        msg = InstanceStatus(module=self.module, instance=self.id, role=ROLE[role], term=self.holder.term,
                             ready=ready, pid=os.getpid(), message=self.message, replica_of=replica_of,
                             replica_seq=replica_seq)
        # frozen: stamped with the moment the outputs were closed (a consumer measures the downtime from it)
        msg.header.stamp = rospy.Time.from_sec(self.frozen_wall if role == 'frozen' else time.time())
        self.status_pub.publish(msg)

    def _on_lease(self, msg: MigrationLease) -> None:
        self.elevator.this_thread()
        with self.lock:
            self.holder.on_answer(Answer(msg.module, msg.term, msg.holder, msg.nonce, msg.granted, msg.duration))
        if msg.granted and msg.holder == self.id and not self.was_active:
            self.wake.set()                   # the first grant of a promotion: the loop opens the outputs now

    def _state_bytes(self) -> bytes:
        return state_codec.encode(self.module, self.hooks.get_state())

    def _renew(self) -> None:
        """A request: a promoted instance's over every path, a standby's (never answered) over the first."""
        with self.lock:
            nonce = self.holder.request(time.monotonic())
            term = self.holder.term
        msg = MigrationRenew(module=self.module, instance=self.id, term=term, nonce=nonce)
        for pub in self.renew_pubs[:len(self.renew_pubs) if term else 1]:
            pub.publish(msg)

    @quiet_at_shutdown
    def _on_control(self, req) -> InstanceControlResponse:
        self.elevator.this_thread()
        try:
            if req.command in ('state', 'ping'):
                ready = not self.dormant and (self.holder.term > 0 or bool(self.hooks.standby_ready()))
                return InstanceControlResponse(ok=True, message='ready' if ready else 'not ready',
                                               term=self.holder.term,
                                               state=self._state_bytes() if req.command == 'state' else b'')
            if req.command == 'freeze':
                with self.lock:
                    if self.holder.term != req.term:
                        return InstanceControlResponse(ok=False, term=self.holder.term,
                                                       message=f'not at term {req.term}')
                    self.frozen = True
                    self.frozen_wall = time.time()
                    data = self.replicator.final(self.hooks.get_state(), req.base_seq)
                self.message = f'frozen at term {req.term}'
                self.hooks.on_frozen()
                self._status()
                threading.Thread(target=self.hooks.after_frozen, name='after-frozen', daemon=True).start()
                rospy.loginfo(f'{self.id}: frozen (term {req.term}); state {len(data)} bytes handed over')
                return InstanceControlResponse(ok=True, message=self.message, term=req.term, state=data)
            if req.command == 'keyframe':
                with self.lock:
                    self.replicator.want_keyframe = True      # the next replica, whole and at once
                self.wake.set()
                return InstanceControlResponse(ok=True, message='a whole state next', term=self.holder.term)
            if req.command in ('sleep', 'wake'):
                return self._sleep_or_wake(req.command)
            if req.command == 'promote':
                self.elevator.boost(self.cfg.promotion_boost)     # the hand-over's path crosses the node's threads
                if self.dormant:
                    return InstanceControlResponse(ok=False, term=self.holder.term,
                                                   message='dormant: wake it first')
                with self.lock:
                    again = (req.term == self.holder.term and not self.frozen and not self.holder.superseded)
                    if not again:
                        with self.prepare_wake:           # no replica given to prepare_state from now on
                            self.to_prepare = None
                        with self.replica_lock:
                            self.prepared = ('', 0)
                        if req.state:
                            with self.replica_lock:       # a patch to a replica it holds: the whole state
                                state = self.replica.resolve(req.base_instance, req.state)
                            self.hooks.set_state(state)   # (refused: nothing changed, the replicas kept)
                            with self.replica_lock:       # the node may change what they share with it
                                self.replica.reset()
                        self.holder.promoted(req.term, req.nonce, req.duration)
                        self.frozen = False
                        self.was_active = False       # reported as "active" anew, not a lapse
                if not again:
                    self._follow_replicas(False)
                    self.message = f'promoted to term {req.term}'
                    rospy.loginfo(f'{self.id}: promoted to term {req.term}'
                                  f'{f" with a state of {len(req.state)} bytes" if req.state else ""}'
                                  f'{" and a lease" if self.active else ""}')
                    self._renew()
                    self._transitions()               # a granted promotion opens the outputs now
                    self._status()
                    self.wake.set()
                return InstanceControlResponse(ok=True, message=self.message, term=req.term, state=b'',
                                               active=self.active)
            return InstanceControlResponse(ok=False, message=f'unknown command {req.command!r}')
        except (ValueError, KeyError, TypeError) as exc:      # a state that does not fit, a stale promotion
            rospy.logwarn(f'{self.id}: {req.command} refused: {exc}')
            return InstanceControlResponse(ok=False, message=str(exc), term=self.holder.term)

    def _sleep_or_wake(self, command: str) -> InstanceControlResponse:
        """``sleep``: a frozen instance, or a standby never promoted (the manager's dormant instance from the
        start), goes dormant; ``wake``: a dormant one becomes a standby (term 0, a fresh lease holder that keeps
        what it has heard of the module's terms)."""
        with self.lock:
            if command == 'sleep' and not self.frozen and self._role() != 'standby':
                return InstanceControlResponse(ok=False, term=self.holder.term,
                                               message=f'only a frozen instance or a standby sleeps (this one is '
                                                       f'{self._role()})')
            if command == 'wake' and not self.dormant:
                return InstanceControlResponse(ok=False, term=self.holder.term,
                                               message=f'not dormant (this one is {self._role()})')
        try:
            if command == 'sleep':
                self.hooks.on_sleep()
            else:
                self.hooks.on_wake()
        except NotImplementedError:
            return InstanceControlResponse(ok=False, term=self.holder.term,
                                           message=f'{self.module} cannot {command}')
        with self.lock:
            if command == 'sleep':
                self.dormant, self.frozen = True, False
                old = self.holder
                self.holder = Holder(self.module, self.id, seen=old.seen, seen_holder=old.seen_holder,
                                     heard=old.heard)
                self.was_active = False
                self.message = 'dormant (retired here; woken by the next migration to this host)'
                with self.replica_lock:         # on_wake resets what prepare_state built
                    self.prepared = ('', 0)
                self._follow_replicas(True)
            else:
                self.dormant = False
                self.message = 'standby (woken)'       # (it kept following the replicas while dormant)
        rospy.loginfo(f'{self.id}: {self.message}')
        self._status()
        self.wake.set()
        return InstanceControlResponse(ok=True, message=self.message, term=self.holder.term)

    def _transitions(self) -> None:
        """Open the outputs when the instance became active (``on_active``), report a lapse when it stopped."""
        with self.activation:
            with self.lock:
                active = self.holder.active(time.monotonic()) and not self.frozen
                lapsed = not active and not self.frozen and not self.holder.superseded
            if active and not self.was_active:
                self.was_active = True
                rospy.loginfo(f'{self.id}: active (term {self.holder.term})')
                self.hooks.on_active()
                self._nudge_bridge()
            elif not active and self.was_active:
                self.was_active = False
                if lapsed:
                    rospy.logwarn(f'{self.id}: lease lapsed (term {self.holder.term}): outputs closed until a '
                                  f'renewal is granted')

    def _nudge_bridge(self) -> None:
        """Ask this host's bridge to poll its master now (``bridge_poll_service``): what ``on_active`` registered
        reaches the other host without waiting for the bridge's next poll. In a thread of its own and never
        waited on; no bridge (a single-master run) is not an error."""
        name = self.cfg.bridge_poll_service
        if not name:
            return

        def call() -> None:
            try:
                rospy.ServiceProxy(name, Empty)()
            except (rospy.ServiceException, rospy.ROSException, OSError) as exc:
                rospy.logdebug(f'{self.id}: no bridge poll ({name}): {exc}')
        threading.Thread(target=call, name='bridge-nudge', daemon=True).start()

    def _renew_loop(self) -> None:
        """Renewal requests every ``renew_period`` (a promoted instance's and a standby's), in a thread of their
        own: a replica being encoded or a status being published in :meth:`_loop` never delays one."""
        self.elevator.this_thread()
        next_renew = time.monotonic()
        while not rospy.core.is_shutdown_requested():
            now = time.monotonic()
            with self.lock:
                asking = not self.frozen and not self.holder.superseded and not (self.dormant and not self.holder.term)
            if asking and now >= next_renew:
                next_renew = now + self.renew_period
                try:
                    self._renew()
                except rospy.ROSException:
                    if rospy.core.is_shutdown_requested():
                        return
                    raise
            time.sleep(max(0.001, min(next_renew - time.monotonic(), self.renew_period / 4)))

    def _loop(self) -> None:
        cfg = self.cfg
        self.elevator.this_thread()
        next_state = next_status = time.monotonic()
        last_role = ''
        while not rospy.core.is_shutdown_requested():
            now = time.monotonic()
            with self.lock:
                promoted = self.holder.term > 0 and not self.frozen and not self.holder.superseded
                standby = self.holder.term == 0 and not self.frozen and not self.dormant
                active = promoted and self.holder.active(now)
                superseded = self.holder.superseded and not self.frozen
                role = self._role()
            try:
                self._transitions()
                if superseded:
                    self.frozen = True
                    self.frozen_wall = time.time()
                    self.message = 'superseded: a newer term was announced'
                    rospy.logwarn(f'{self.id}: superseded (term {self.holder.term} is over): outputs closed, '
                                  f'shutting down')
                    self.hooks.on_frozen()
                    self.hooks.after_frozen()
                    self._status()
                    rospy.signal_shutdown('superseded by a newer term')
                    return
                if active and (now >= next_state or self.replicator.want_keyframe):
                    next_state = now + self.replicate_period
                    self._publish_state()
                if standby:
                    self._ask_keyframe(now)
                if role != last_role or now >= next_status:
                    last_role = role
                    next_status = now + cfg.status_period
                    self._status()
            except rospy.ROSException:
                if rospy.core.is_shutdown_requested():
                    return
                raise
            self.wake.wait(min(self.renew_period, cfg.replicate_period, cfg.status_period) / 4)
            self.wake.clear()

    def _publish_state(self) -> None:
        seq, base, data = self.replicator.next(self.hooks.get_state())
        msg = ModuleState(module=self.module, instance=self.id, term=self.holder.term, seq=seq, base_seq=base,
                          data=data)
        msg.header.stamp = rospy.Time.from_sec(time.time())
        self.state_pub.publish(msg)


    # ------------------------------------------------------------------ replicas (as a standby)
    def _follow_replicas(self, on: bool) -> None:
        """Only a standby subscribes to the replicas: a subscriber on the other host is one more node its master
        must notify of every change of the topic's publishers, and a master's notification to a host cut off
        blocks one of its few notifier threads until TCP gives up (minutes)."""
        if on and self.replica_sub is None:
            self.replica_sub = rospy.Subscriber(topic(self.module, 'state'), ModuleState, self._on_replica,
                                                queue_size=5)
        elif not on and self.replica_sub is not None:
            self.replica_sub.unregister()
            self.replica_sub = None

    @quiet_at_shutdown
    def _on_replica(self, msg: ModuleState) -> None:
        if msg.instance == self.id:
            return
        with self.lock:      # a dormant instance keeps them too: woken, it is promotable with a patch at once
            standby = self.holder.term == 0 and not self.frozen
            dormant = self.dormant
        if not standby:
            return
        try:
            with self.replica_lock:
                first = self.replica.instance != msg.instance
                taken = self.replica.take(msg.instance, msg.seq, msg.base_seq, bytes(msg.data))
                newest = self.replica.state
        except state_codec.StateError as exc:
            rospy.logwarn(f'{self.id}: replica {msg.seq} of {msg.instance} ignored: {exc}')
            return
        if not taken and not dormant:
            self._keyframe_missing(msg.instance, msg.seq)
        if taken and first and not self.prepares:
            self._status()            # the manager waits for this before a migration here freezes the source
        if taken and not dormant and self.prepares:
            with self.prepare_wake:
                self.to_prepare = (msg.instance, msg.seq, newest)
                self.prepare_wake.notify()

    def _prepare_loop(self) -> None:
        """Give the newest replica to ``prepare_state`` while a standby (see :meth:`Hooks.prepare_state`). The
        promotion takes ``self.lock``; a replica is handed over only under it, while still a standby. The status
        names the newest replica prepared, and is sent at once for the first of an instance: a migration here
        waits for it, so that the promotion does not wait for a prepare_state still running (the store's first,
        of thousands of measurements, takes 0.4 s on the capped robot in bench_migration.sh)."""
        while not rospy.core.is_shutdown_requested():
            with self.prepare_wake:
                self.prepare_wake.wait_for(lambda: self.to_prepare is not None, timeout=1.0)
                item, self.to_prepare = self.to_prepare, None
            if item is None:
                continue
            instance, seq, state = item
            with self.lock:
                if self.holder.term != 0 or self.frozen or self.dormant:
                    continue
            try:
                self.hooks.prepare_state(state)
            except ValueError as exc:
                rospy.logwarn(f'{self.id}: replica not prepared: {exc}')
                continue
            with self.lock, self.replica_lock:      # (not if promoted meanwhile: the promotion reset it)
                if self.holder.term != 0 or self.frozen:
                    continue
                first = self.prepared[0] != instance
                self.prepared = (instance, seq)
            if first:
                self._status()

    def _ask_keyframe(self, now: float) -> None:
        """A standby that holds no replica of the current holder asks it for a whole state (at most once per
        ``timeouts.control_call``; never waited on)."""
        holder = self.holder.seen_holder
        if not holder or now - self.keyframe_asked < self.cfg.control_call:
            return
        with self.replica_lock:
            if self.replica.seq_of(holder):
                return
        self.keyframe_asked = now
        self._request_keyframe(holder)

    def _keyframe_missing(self, instance: str, seq: int) -> None:
        """Replicas of ``instance`` arrive but are patches to one this standby does not hold: ask for a whole
        state, and again when two more came since the last request without one (a whole state sent before this
        standby's subscription had connected is never seen: a woken instance subscribed anew waited for its next
        request, ``timeouts.control_call`` later, and missed every migration's ``timeouts.replica``)."""
        with self.replica_lock:
            if self.keyframe_missing[0] == instance and seq <= self.keyframe_missing[1] + 2:
                return
            self.keyframe_missing = (instance, seq)
        self.keyframe_asked = time.monotonic()
        self._request_keyframe(instance)

    def _request_keyframe(self, holder: str) -> None:
        name = topic(self.module, f'{host_of(holder)}/control')

        def call() -> None:
            ok, res = call_with_timeout(rospy.ServiceProxy(name, InstanceControl), self.cfg.control_call,
                                        command='keyframe')
            if not ok:
                rospy.logdebug(f'{self.id}: keyframe request to {holder} failed: {res}')
        threading.Thread(target=call, name='keyframe-request', daemon=True).start()
