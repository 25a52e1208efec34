"""Leases and terms: at most one active instance of a module at any moment (fencing), without synchronised
clocks.

The manager on the robot is the only grantor. Each module has a *term* (a number that only grows) and at most
one *holder* (an instance: ``module@host``). An instance may produce output only while it holds a valid lease
for the current term:

- The holder asks for a renewal (``request``) every ``renew_period`` seconds, remembering the local monotonic
  time ``t0`` at which it sent each request. When the grantor answers, the lease is valid until
  ``t0 + duration`` on the *holder's* clock. Since ``t0`` precedes the grant, the holder's lease always ends no
  later than the grantor believes it does: no clock synchronisation is needed, and a late or repeated answer
  (queued during an outage) can only grant a lease that has already run out.
- The grantor records ``valid_until = grant time + duration`` on its own clock. It gives the module to another
  instance only when (a) the holder has confirmed it stopped (``release``: frozen for a planned migration), or
  (b) ``valid_until + margin`` has passed (the holder is cut off and has demoted itself by then).
- A promoted instance produces no output before it holds a lease for the new term; the grantor answers renewals
  only for the current term and holder. A promotion may carry the lease itself (:meth:`Grantor.pregrant`): a
  standby sends requests too (term 0, never answered), and the promotion grants the newest one the grantor has
  received. The instance is then active the moment the order arrives, valid until *that request's* send time +
  ``duration`` (so still no later than the grantor believes: the request was sent before the grantor received it,
  which was before the promotion), without a round trip for its first renewal. The grantor counts such a lease
  as granted at the promotion: a promotion it rolls back is waited out (``free_at``) like any lease. A promotion
  without a pre-grant that the grantor later rolled back can never produce output, even if the order reaches the
  instance late.

The lease's length may depend on the holder's host (``host_durations``): an instance on the grantor's own host
never crosses the link, and on a saturated robot its renewal may queue behind bulk work, so it gets a longer
lease there, while one across the link gets a short one (its failover waits for it to run out). Every answer
carries the duration it grants, so the holder always counts with the grantor's.

A request may reach the grantor more than once (sent over several connections, so that a stalled one does not
starve the lease): :meth:`Grantor.first_receipt` tells the first copy from the others, which need no answer.

``margin`` covers clock *rate* differences (monotonic clocks drift by ppm) and the time the holder needs to stop
its outputs once its lease ends. These classes hold no ROS types and read no clock: callers pass ``now``
(monotonic seconds).
"""
from __future__ import annotations

import random
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple


INSTANCE_HEADER = 'cnr_instance'       # connection header of a managed instance's output publishers: its id


def instance_id(module: str, host: str) -> str:
    """The name of a module's instance on a host, e.g. ``mfg@cloud``."""
    return f'{module}@{host}'


def host_of(instance: str) -> str:
    return instance.rpartition('@')[2]


@dataclass(frozen=True)
class Answer:
    """The grantor's answer to a renewal request (published on the lease topic)."""
    module: str
    term: int
    holder: str                 # the current holder ('' = none)
    nonce: int                  # the request's nonce (0 for an unsolicited announcement)
    granted: bool               # True: the requester holds the lease for ``duration`` from its request
    duration: float


class Grantor:
    """The manager's side for one module."""

    RECEIPTS = 256            # requests remembered to tell a copy (another connection's) from a new one

    def __init__(self, module: str, duration: float, margin: float, term: int = 0,
                 host_durations: Optional[Dict[str, float]] = None) -> None:
        """``duration``: the lease's length; ``host_durations``: host -> the length for a holder on that host
        instead."""
        if duration <= 0 or margin < 0 or any(d <= 0 for d in (host_durations or {}).values()):
            raise ValueError('lease duration must be > 0 and margin >= 0')
        self.module = module
        self.duration = duration
        self.host_durations = dict(host_durations or {})
        self.margin = margin
        self.receipts: 'OrderedDict[Tuple[str, int], None]' = OrderedDict()
        self.term = term
        self.holder = ''
        self.valid_until = float('-inf')     # grantor clock: the last holder may be active until then
        self.standby: Dict[str, Tuple[int, float]] = {}     # instance -> (nonce, receipt) of its newest request

    def duration_of(self, instance: str) -> float:
        """The lease's length for ``instance`` (by its host)."""
        return self.host_durations.get(host_of(instance), self.duration)

    def first_receipt(self, instance: str, nonce: int) -> bool:
        """True for the first copy of ``instance``'s request ``nonce`` to arrive, False for a later copy."""
        key = (instance, nonce)
        if key in self.receipts:
            return False
        self.receipts[key] = None
        while len(self.receipts) > self.RECEIPTS:
            self.receipts.popitem(last=False)
        return True

    def free_at(self) -> float:
        """When another instance may be promoted: once every lease granted so far has run out (+ margin)."""
        return self.valid_until + self.margin

    def may_promote(self, now: float) -> bool:
        return now >= self.free_at()

    def promote(self, instance: str, now: float) -> int:
        """Give the module to ``instance`` under a new term; returns the term. Refused (ValueError) while an
        earlier holder may still be active. The new holder is not active before its first granted renewal."""
        if not self.may_promote(now):
            raise ValueError(f'{self.module}: {self.holder or "the last holder"} may be active for '
                             f'{self.free_at() - now:.3f} s more')
        self.term += 1
        self.holder = instance
        return self.term

    def release(self, instance: str, term: int) -> bool:
        """The holder confirms it has stopped producing output for good (frozen for a planned migration):
        the module is free at once. Later renewals of that term are refused."""
        if instance == self.holder and term == self.term:
            self.holder = ''
            self.term += 1
            self.valid_until = float('-inf')
            return True
        return False

    def revoke(self) -> None:
        """Take the module from its holder (e.g. a promotion rolled back): renewals of its term are refused
        from now on; a lease already granted runs out by itself (see :meth:`free_at`)."""
        if self.holder:
            self.holder = ''
            self.term += 1

    def standby_request(self, instance: str, nonce: int, now: float) -> None:
        """A standby's request (term 0): not answered, remembered for a promotion's pre-grant."""
        self.standby[instance] = (nonce, now)

    def pregrant(self, instance: str, now: float) -> Tuple[int, float]:
        """For a promotion of ``instance`` (the holder, just promoted) sent now: the nonce of its newest standby
        request received within a lease ``duration`` (0: none) and the duration. The lease counts as granted now
        (``valid_until``), so a rollback waits for it to run out."""
        duration = self.duration_of(instance)
        nonce, received = self.standby.pop(instance, (0, float('-inf')))
        if instance != self.holder or not nonce or now - received >= duration:
            return 0, duration
        self.valid_until = max(self.valid_until, now + duration)
        return nonce, duration

    def request(self, instance: str, term: int, nonce: int, now: float) -> Answer:
        """A renewal request from ``instance`` for ``term``: granted only to the current holder and term."""
        granted = bool(self.holder) and instance == self.holder and term == self.term
        duration = self.duration_of(instance)
        if granted:
            self.valid_until = max(self.valid_until, now + duration)
        return Answer(self.module, self.term, self.holder, nonce, granted, duration)

    def announcement(self) -> Answer:
        return Answer(self.module, self.term, self.holder, 0, False, self.duration)


@dataclass
class Holder:
    """An instance's side: is it allowed to produce output now?"""
    module: str
    instance: str
    term: int = 0               # the term it was promoted to (0: standby, never active)
    valid_until: float = float('-inf')
    # nonces start at random: a restarted instance (same name) cannot be granted a lease for an earlier process's
    # request it sent at another time
    next_nonce: int = field(default_factory=lambda: random.randrange(1, 2 ** 31))
    sent: Dict[int, float] = field(default_factory=dict)    # nonce -> local send time
    superseded: bool = False    # a newer term or another holder was announced: this instance is done
    seen: int = 0               # the highest term announced so far (a promotion must not be older)
    seen_holder: str = ''       # the holder announced with it
    heard: bool = False         # an announcement or answer of the module's grantor has arrived (``seen`` is known)

    def promoted(self, term: int, nonce: int = 0, duration: float = 0.0) -> None:
        """Promotion to ``term``: active at once if it carries a grant (``nonce``: one of the standby requests
        this instance sent, valid until that request's send time + ``duration``), else from the first granted
        renewal."""
        if term <= self.term or term < self.seen or (term == self.seen and self.seen_holder != self.instance):
            raise ValueError(f'{self.instance}: promotion to term {term}, but term {max(self.term, self.seen)} '
                             f'was already seen')
        t0 = self.sent.get(nonce) if nonce else None
        self.term = term
        self.valid_until = float('-inf') if t0 is None else t0 + duration
        self.sent.clear()
        self.superseded = False

    def request(self, now: float) -> int:
        """A renewal request is sent now: returns its nonce (only the last few are remembered)."""
        nonce = self.next_nonce
        self.next_nonce = self.next_nonce % (2 ** 32 - 1) + 1
        self.sent[nonce] = now
        while len(self.sent) > 64:                 # the oldest first (insertion order)
            del self.sent[next(iter(self.sent))]
        return nonce

    def on_answer(self, a: Answer) -> None:
        if a.module != self.module:
            return
        self.heard = True
        if a.term > self.seen:       # the announcement of this very promotion may arrive before the order
            self.seen, self.seen_holder = a.term, a.holder
        if self.term == 0:
            return
        if a.term > self.term or (a.term == self.term and a.holder != self.instance):
            self.superseded = True            # someone else's term: never active again
            self.valid_until = float('-inf')
            return
        if a.granted and a.term == self.term and a.holder == self.instance:
            t0 = self.sent.pop(a.nonce, None)
            if t0 is not None:
                self.valid_until = max(self.valid_until, t0 + a.duration)

    def active(self, now: float) -> bool:
        return self.term > 0 and not self.superseded and now < self.valid_until


class TermFilter:
    """A consumer's side: accept a message from an instance only if it is the current holder of its module
    according to the newest announcement heard (unmanaged modules, never announced, are accepted)."""

    def __init__(self) -> None:
        self.current: Dict[str, Answer] = {}

    def on_answer(self, a: Answer) -> None:
        known = self.current.get(a.module)
        if known is None or a.term >= known.term:
            self.current[a.module] = a

    def accept(self, module: str, instance: Optional[str]) -> bool:
        known = self.current.get(module)
        if known is None or instance is None:
            return True
        return bool(known.holder) and instance == known.holder
