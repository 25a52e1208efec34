"""local_mapcell_manager movable by migration_manager: the managed instance's hooks around a
:class:`~local_mapcell_manager.node.ManagerNode` (README "Migration state"), and the executable's entry point.

As a managed standby the node buffers ``merged_measurements`` but stores, publishes and serves nothing, and the
hooks here prepare the store from the active instance's replicas; on promotion they take over the handed-over
store (every measurement) and replay the buffer over it, so the measurements stored end up exactly once; frozen,
the node's latched cell_states and services are unregistered once the freeze was answered.
"""
from __future__ import annotations

import threading
from typing import Any, Dict, Optional

import rospy

import cnr_params
from cnr_params.ros import private_section
from cnr_runtime import init_node
from local_mapcell_manager.core.ledger import Prepared, state_newest
from local_mapcell_manager.core.params import read_params
from local_mapcell_manager.core.relay import STATE_KEY, state_mark
from local_mapcell_manager.core.store import MeasurementStore
from local_mapcell_manager.node import ManagerNode, StoreHooks
from migration_manager.instance import Retiring


class StoreMigration(StoreHooks):
    """The hooks of a :class:`ManagerNode`'s managed instance (created by the node with its store, before its
    instance). Lock order as the node's: the instance's lock, then ``node.lock``."""

    def __init__(self, node: ManagerNode, store: MeasurementStore) -> None:
        self.node = node
        self.retiring = Retiring()
        # a standby's store prepared from the replicas (None once promoted); its own lock, never held with
        # node.lock by prepare_state, so a replica is prepared while measurements keep arriving
        self.prepare_lock = threading.Lock()
        self.prepared: Optional[Prepared] = Prepared(node.grid, store)
        rospy.on_shutdown(self.discard_prepared)

    def standby_ready(self) -> bool:
        """Connected to the merged measurements' publishers, or none is registered yet and no instance of the
        module was ever promoted (the mission's first instance: the two-host mission starts the merger only once a
        store is active, so waiting for it here would wait forever). Which of the two it is, the manager's
        announcements say (term 0: never promoted): not ready before one has arrived. Once a term has been
        announced a merger runs: a standby whose master does not list it (e.g. on the cloud just after an
        outage, before the bridge has restored the registration) is not ready, or what the merger publishes
        until it connects would reach no store. Through the relay: always ready (the sender keeps what no
        active instance acknowledged and sends it again to the one promoted)."""
        if self.node.relay is not None:
            return self.node.instance is not None
        sub, instance = self.node.sub, self.node.instance
        if sub is None or instance is None:
            return False
        if sub.get_num_connections() > 0:
            return True
        holder = instance.holder
        if not holder.heard or holder.seen > 0:
            return False
        try:
            return all(name != sub.resolved_name for name, _type in rospy.get_published_topics())
        except (rospy.ROSException, OSError):
            return False

    def get_state(self) -> Dict[str, Any]:
        node = self.node
        with node.instance.lock, node.lock:            # (reentrant: a freeze calls this holding instance.lock)
            node._sync_frozen()
            state = node.ledger.state()
            if node.relay is not None:                  # the mark that matches this store
                state[STATE_KEY] = node.relay.mark()
            return state

    def set_state(self, state: Dict[str, Any]) -> None:
        node = self.node
        mark = state_mark(state) if node.relay is not None else None      # ValueError: refused
        with node.lock:
            since = None if mark is not None else node.ledger.missing_since(state_newest(state))
        recovered = node._recover(since)
        with node.lock, self.prepare_lock:
            added = node.ledger.recover(recovered)
            replay = node.ledger.restore(state, self.prepared)     # ValueError: refused, nothing changed
            self.prepared = None
            node._dirty = True
            count = node.ledger.count
            if mark is not None:
                node.relay.adopt(mark)                  # acknowledged from here once active: the rest comes again
        ahead = 'restored whole' if replay.prepared is None else f'{replay.prepared} prepared ahead'
        relay = '' if mark is None else f'relay mark: epoch {mark["epoch"]}, up to seq {mark["delivered"]}; '
        rospy.loginfo(f'state taken over: {count} measurements ({ahead}); {relay}'
                      f'{node._recovered(since, recovered, added)}{node._replayed(replay)}')

    def prepare_state(self, state: Dict[str, Any]) -> None:
        """A replica of the active instance: what it adds is checked, filed and written into a draft of the
        store now, so the promotion's set_state handles only what its state adds (ledger.Prepared)."""
        with self.prepare_lock:
            if self.prepared is None:                   # promoted meanwhile
                return
            try:
                self.prepared.update(state)
            except OSError as exc:
                raise ValueError(f'cannot write a draft of the store next to {self.node.p.store}: {exc}') from None

    def discard_prepared(self) -> None:
        """Promoted without a state, or shutting down: the prepared store is not used."""
        if self.prepare_lock.acquire(timeout=1.0):
            try:
                prepared, self.prepared = self.prepared, None
                if prepared is not None:
                    prepared.discard()
            finally:
                self.prepare_lock.release()

    def on_active(self) -> None:
        self.node.activate()
        self.retiring.close()                           # (promoted again before after_frozen ran: same names)
        self.node.open_services()

    def on_frozen(self) -> None:
        with self.node.instance.lock:
            self.retiring.add(*self.node.close_outputs())

    def after_frozen(self) -> None:
        """The services (they refuse while frozen) and the latched cell_states (none of a frozen instance for late
        subscribers) are unregistered once the freeze was answered."""
        self.retiring.close()


@cnr_params.exit_on_config_error
def main() -> None:
    init_node('local_mapcell_manager')
    ManagerNode(read_params(private_section('~')), StoreMigration)
    rospy.spin()
