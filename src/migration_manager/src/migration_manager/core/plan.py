"""One migration of one module as a state machine: make-before-break, exactly one active, rollback.

Both of the thesis's methods (§4.2.1, Fig. 4-12) run through the same steps; they differ in where the target
instance comes from:

- **cold** (method 1, "stop it, save its state, start a clone with that state"): the target instance is started
  for this migration, as a *standby* (inputs connected, outputs closed), and the source is stopped at the end.
  Unlike the thesis's order, the clone starts *before* the state is taken, so input that arrives while the state
  moves is buffered by the clone rather than lost, and the source keeps working while the clone starts: the
  output gap is the hand-over only, not the ≈5 s start-up (Table 4-2).
- **hot** (method 2, the hibernating proxy, the thesis's future work): the standby already runs on the target,
  its state replicated continuously; the source becomes the standby when it is done.

Steps: ``STARTING`` (cold: wait for the target standby to be ready; hot and cold: and, at most
``timeouts.replica``, for it to hold a replica of the source, so that the final state can come as a patch to
it) → ``FREEZING`` (the source closes its outputs
for good and returns its final state; the lease is released) → ``PROMOTING`` (the target restores that state,
replays what it buffered, and is active once its first lease renewal is granted) → ``DONE`` (the source is
stopped or goes back to standby). If the source cannot be reached to freeze it (cut off), the target is promoted
with the last replicated state once the source's lease has run out: never two active. If the target fails or
times out, the migration is rolled back: before the freeze nothing has changed; after it the source is promoted
again under a new term (it never stopped running), so the module is never without an active instance for longer
than the configured timeouts. A *recovery* is a failover on the same host: the robot's own active instance was
lost (it exited and its agent restarted it as a standby); the standby is promoted with the last replicated state
once the old lease has run out.

The class performs no I/O: each event returns the actions for the caller (the manager node) to carry out.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

from migration_manager.core.lease import Grantor, instance_id

MODES = ('cold', 'hot')


class Step(enum.Enum):
    STARTING = 'starting'
    FREEZING = 'freezing'
    WAITING_LEASE = 'waiting_lease'       # the source is cut off: wait until its lease has run out
    PROMOTING = 'promoting'
    ROLLING_BACK = 'rolling_back'
    DONE = 'done'
    ROLLED_BACK = 'rolled_back'
    FAILED = 'failed'


# actions for the node: (verb, host, detail)
Action = Tuple[str, str, object]


@dataclass(frozen=True)
class Timeouts:
    start: float                 # [s] a cold target standby must be ready within this
    freeze: float                # [s] the source must answer the freeze within this (else: treated as cut off)
    promote: float               # [s] the target must be active within this after the promotion order
    replica: float               # [s] a ready target standby that holds no replica of the source yet is waited
                                 #   for this long (the freeze then hands over a patch, not the whole state)


@dataclass
class Event:
    """A migration event for the manager's ``~events`` topic."""
    at: float
    step: str
    message: str


@dataclass
class Migration:
    module: str
    source: str                  # host of the active instance ('' if none is active)
    target: str
    mode: str
    timeouts: Timeouts
    grantor: Grantor
    started: float
    step: Step = Step.STARTING
    deadline: float = 0.0
    state: Optional[bytes] = None          # the state handed over
    replicated: Optional[bytes] = None     # the newest state the active instance replicated (kept by the node)
    failover: bool = False                 # the source is known to be cut off: do not try to freeze it
    state_source: str = ''                 # 'frozen' (final state) or 'replicated' (last known)
    frozen_at: Optional[float] = None      # when the source's output stopped (or its lease ran out)
    active_at: Optional[float] = None
    term: int = 0
    events: List[Event] = field(default_factory=list)
    error: str = ''
    woken: bool = False                    # the target standby was a dormant instance woken, not a clone
    replica_wait: Optional[float] = None   # until when a ready target is waited for to hold a replica

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f'mode must be one of {", ".join(MODES)}, got {self.mode!r}')
        if self.source == self.target and not self.failover:
            raise ValueError(f'{self.module} is already on {self.target}')

    # ------------------------------------------------------------------ helpers
    def _note(self, now: float, message: str) -> None:
        self.events.append(Event(now, self.step.value, message))

    @property
    def recovery(self) -> bool:
        """A failover on the same host: its active instance was lost (exited, restarted by its agent as a
        standby) and that standby takes over with the last replicated state once the old lease ran out."""
        return self.failover and self.source == self.target

    @property
    def finished(self) -> bool:
        return self.step in (Step.DONE, Step.ROLLED_BACK, Step.FAILED)

    @property
    def downtime(self) -> Optional[float]:
        """Manager-side estimate: from the source's freeze (or lease end) to the target's first granted lease."""
        if self.frozen_at is None or self.active_at is None:
            return None
        return self.active_at - self.frozen_at

    # ------------------------------------------------------------------ events
    def begin(self, now: float, target_standby_ready: bool, holds_replica: bool = True) -> List[Action]:
        """Start: a hot migration with a ready standby freezes at once (once it holds a replica of the source,
        see :meth:`target_ready`); otherwise a standby is started."""
        self.step = Step.STARTING
        self.deadline = now + self.timeouts.start
        if target_standby_ready:
            return self.target_ready(now, holds_replica)
        self._note(now, f'starting a standby on {self.target}')
        return [('start_standby', self.target, None)]

    def target_ready(self, now: float, holds_replica: bool = True) -> List[Action]:
        """The target standby is ready. The freeze waits, at most ``timeouts.replica``, until the standby also
        holds a replica of the source (``holds_replica``; a standby started moments ago has none yet): the final
        state then comes as a patch to it, not whole (thousands of measurements for the store). Not waited for
        without a source to freeze or in a failover (no freeze: the last replicated state goes)."""
        if self.step is not Step.STARTING:
            return []
        if not holds_replica and self.source and not self.failover:
            if self.replica_wait is None:
                self.replica_wait = now + self.timeouts.replica
                if self.timeouts.replica > 0:
                    self._note(now, f'standby on {self.target} is ready; waiting for it to hold a replica of '
                                    f'{instance_id(self.module, self.source)} (at most {self.timeouts.replica:g} s)')
            if now < self.replica_wait:
                return []
            self._note(now, f'standby on {self.target} is ready (without a replica: the whole state goes)')
        else:
            self._note(now, f'standby on {self.target} is ready')
        return self._freeze(now)

    def _freeze(self, now: float) -> List[Action]:
        if not self.source:            # nothing active anywhere (e.g. the first start): promote at once
            self.frozen_at = now
            return self._promote(now)
        self.step = Step.FREEZING
        if self.failover:
            return self.source_unreachable(now)
        self.deadline = now + self.timeouts.freeze
        self._note(now, f'freezing {instance_id(self.module, self.source)}')
        return [('freeze', self.source, self.grantor.term)]

    def frozen(self, now: float, state: bytes) -> List[Action]:
        """The source confirms: outputs closed for good, final state attached."""
        if self.step is not Step.FREEZING:
            return []
        self.grantor.release(instance_id(self.module, self.source), self.grantor.term)
        self.state, self.state_source, self.frozen_at = state, 'frozen', now
        self._note(now, f'state transferred ({len(state)} bytes)')
        return self._promote(now)

    def source_unreachable(self, now: float) -> List[Action]:
        """The freeze was not answered: the source may be cut off. Wait for its lease to run out, then promote
        the target with the last replicated state (never two active)."""
        if self.step is not Step.FREEZING:
            return []
        self.grantor.revoke()                  # its renewals are refused from now on
        self.state, self.state_source = self.replicated, 'replicated'
        self.step = Step.WAITING_LEASE
        self._note(now, f'{self.source} does not answer: waiting for its lease to run out '
                        f'({max(0.0, self.grantor.free_at() - now):.2f} s)')
        return self.tick(now)

    def _promote(self, now: float) -> List[Action]:
        self.term = self.grantor.promote(instance_id(self.module, self.target), now)
        self.step = Step.PROMOTING
        self.deadline = now + self.timeouts.promote
        self._note(now, f'promoting {instance_id(self.module, self.target)} to term {self.term}')
        return [('promote', self.target, (self.term, self.state))]

    def target_active(self, now: float, term: int) -> List[Action]:
        if self.step is not Step.PROMOTING or term != self.term:
            return []
        self.active_at = now
        self.step = Step.DONE
        dt = self.downtime
        self._note(now, f'switched to {self.target} (term {term}); hand-over {1000 * dt:.0f} ms'
                        if dt is not None else f'switched to {self.target} (term {term})')
        if not self.source or self.recovery:
            return []
        return [('retire', self.source, self.mode)]

    def target_failed(self, now: float, why: str) -> List[Action]:
        """The target crashed, refused, or timed out: roll back."""
        if self.finished or self.step is Step.ROLLING_BACK:
            return []
        self.error = why
        if self.recovery:
            # the host's own instance was lost and its restart did not take over: its agent restarts it again
            # (stopping it would leave the host without one) and the manager recovers once it is ready
            self.grantor.revoke()
            self.step = Step.FAILED
            self._note(now, f'recovery on {self.target} failed ({why}): no active instance until the next try')
            return []
        if self.step is Step.STARTING:
            self.step = Step.ROLLED_BACK       # nothing handed over: the source never stopped
            self._note(now, f'rolled back before the hand-over: {why}')
            return [('stop', self.target, None)]
        reachable = self.step is not Step.WAITING_LEASE and self.state_source != 'replicated'
        self.grantor.revoke()
        actions: List[Action] = [('stop', self.target, None)]
        if self.source and reachable:
            # the source still runs (frozen, or its freeze unanswered): promote it again under a new term once
            # any lease the target may have been granted has run out
            self.step = Step.ROLLING_BACK
            self._note(now, f'target failed ({why}): reinstating {self.source}')
            return actions + self.tick(now)
        self.step = Step.FAILED
        self._note(now, f'target failed ({why}) and the source is unreachable: no active instance')
        return actions

    def tick(self, now: float) -> List[Action]:
        """Time passes: deadlines and waiting for leases."""
        if self.step is Step.WAITING_LEASE and self.grantor.may_promote(now):
            self.frozen_at = self.grantor.free_at() if self.grantor.free_at() != float('-inf') else now
            self._note(now, f'lease of {self.source} ran out')
            return self._promote(now)
        if self.step is Step.ROLLING_BACK and self.grantor.may_promote(now):
            self.term = self.grantor.promote(instance_id(self.module, self.source), now)
            self.step = Step.ROLLED_BACK
            self._note(now, f'{self.source} promoted again (term {self.term})')
            # without a state: the source keeps its own (the one it froze with, and what it took in since); sending
            # its frozen state back gained nothing, and a state it refused would have left no active instance
            return [('promote', self.source, (self.term, None))]
        if self.step in (Step.STARTING, Step.PROMOTING) and now > self.deadline:
            return self.target_failed(now, f'{self.step.value} timed out')
        if self.step is Step.FREEZING and now > self.deadline:
            return self.source_unreachable(now)
        return []
