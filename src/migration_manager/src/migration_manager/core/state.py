"""The state a module hands over in a migration: a JSON object, zlib-compressed on the wire — whole, or as a
*patch* to a state the receiver already holds.

Each movable node documents the keys of its state in its README ("Migration state"). Floats that are not
finite (NaN, inf) are kept (Python's JSON writes them as NaN/Infinity and reads them back).

Why patches: local_mapcell_manager's state is its whole store, 191 KB compressed after 5700 measurements (hot
bench of 2026-11-26), and grows with the mission. Sent whole, it crossed a 100 ms link in 4-5 round trips (TCP
slow start: hand-over 0.42-0.55 s against about one round trip for the other modules), and the cloud instance's
replica every 0.5 s was 3 Mbit/s on the link. A patch holds what changed since the base: the keys whose value
changed, and for a list that only grew (a store's columns) the items appended.

- :func:`diff` / :func:`patch`: the patch from one JSON value to another and its application;
- :class:`Replicator` (the active instance): each replica a patch to the previous one, a whole state every
  ``keyframe_every`` replicas or when asked (a new standby's base); the final state of a freeze a patch to a
  replica the receiver says it holds;
- :class:`Replica` (the manager and the standbys): the newest replica of a module's active instance, kept by
  applying the stream; resolves a patch made against it into the whole state.
"""
from __future__ import annotations

import json
import zlib
from collections import OrderedDict
from typing import Any, Dict, Optional, Tuple


class StateError(ValueError):
    """A state that cannot be decoded or does not belong to the module."""


class BaseMissing(StateError):
    """A patch whose base state the receiver does not hold (it needs the whole state)."""


#: zlib level: 1, not the default 6. The active instance encodes its state every replicate_period; for a
#: store of 3000 measurements (387 KB of JSON) level 6 took 20 ms and level 1 3.5 ms of this machine's CPU for
#: 7 % more bytes (181 vs 194 KB; JSON itself 7.8 ms): at 2 Hz, level 6's compression alone was 0.04 CPU, 12 %
#: of the robot's third of a CPU.
COMPRESSION = 1

#: message prefix of a promotion refused for a patch whose base the target does not hold (the manager then
#: sends the whole state)
BASE_MISSING = 'base state missing'


# ---------------------------------------------------------------------------- patches
def diff(base: Any, new: Any) -> Dict[str, Any]:
    """The patch that turns ``base`` into ``new``: ``{"=": value}`` (replaced), ``{"+": items}`` (a list that
    only grew: the items appended), ``{"{": {key: patch}, "-": [keys]}`` (an object: the keys that changed,
    the keys removed). Values are compared with ``==`` (a NaN never equals itself: such a value is sent again)."""
    if isinstance(base, dict) and isinstance(new, dict):
        changed = {k: diff(base[k], v) if k in base else {'=': v} for k, v in new.items()
                   if k not in base or base[k] != v}
        out: Dict[str, Any] = {'{': changed}
        removed = [k for k in base if k not in new]
        if removed:
            out['-'] = removed
        return out
    if isinstance(base, list) and isinstance(new, list) and len(new) >= len(base) and new[:len(base)] == base:
        return {'+': new[len(base):]}
    return {'=': new}


def patch(base: Any, p: Any, field: str = 'state') -> Any:
    """``base`` with the patch ``p`` applied (``base`` is not changed; unchanged parts are shared).

    Raises:
        StateError: ``p`` is not a patch of ``base`` (``field`` names where).
    """
    if not isinstance(p, dict) or len(p) == 0:
        raise StateError(f'patch at {field}: not a patch')
    if '=' in p:
        return p['=']
    if '+' in p:
        if not isinstance(base, list) or not isinstance(p['+'], list):
            raise StateError(f'patch at {field}: appends to a {type(base).__name__}')
        return base + p['+']
    if '{' in p:
        if not isinstance(base, dict) or not isinstance(p['{'], dict):
            raise StateError(f'patch at {field}: changes keys of a {type(base).__name__}')
        out = {k: v for k, v in base.items() if k not in p.get('-', ())}
        for k, sub in p['{'].items():
            out[k] = patch(base.get(k), sub, f'{field}.{k}')
        return out
    raise StateError(f'patch at {field}: unknown operation {sorted(p)}')


# ---------------------------------------------------------------------------- the wire
def _pack(doc: Dict[str, Any]) -> bytes:
    return zlib.compress(json.dumps(doc, separators=(',', ':')).encode(), COMPRESSION)


def encode(module: str, state: Dict[str, Any]) -> bytes:
    """The whole state."""
    return _pack({'module': module, 'state': state})


def encode_patch(module: str, base_seq: int, p: Dict[str, Any]) -> bytes:
    """A patch to the state its sender replicated as ``base_seq``."""
    return _pack({'module': module, 'base': base_seq, 'patch': p})


def decode_any(module: str, data: bytes) -> Tuple[int, Any]:
    """``(0, state)`` for a whole state, ``(base_seq, patch)`` for a patch."""
    try:
        doc = json.loads(zlib.decompress(bytes(data)).decode())
    except (zlib.error, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StateError(f'state of {module}: not a compressed JSON state ({exc})') from None
    if not isinstance(doc, dict) or doc.get('module') != module:
        raise StateError(f'state of {module}: made by {doc.get("module") if isinstance(doc, dict) else "?"!r}')
    if isinstance(doc.get('state'), dict):
        return 0, doc['state']
    base = doc.get('base')
    if isinstance(base, int) and not isinstance(base, bool) and base > 0 and isinstance(doc.get('patch'), dict):
        return base, doc['patch']
    raise StateError(f'state of {module}: neither a state nor a patch')


def decode(module: str, data: bytes) -> Dict[str, Any]:
    """A whole state (a patch raises :class:`BaseMissing`: resolve it with a :class:`Replica`)."""
    base, doc = decode_any(module, data)
    if base:
        raise BaseMissing(f'{BASE_MISSING}: state of {module} is a patch to replica {base}')
    return doc


# ---------------------------------------------------------------------------- both ends of the stream
class Replicator:
    """The active instance's side: what to publish as the next replica and what to hand over at a freeze.

    Keeps its last ``keep`` replicas (the receivers may be one behind). ``get_state`` must return a fresh
    structure the node does not change afterwards (every movable node's does: its README, "Migration state").
    """

    def __init__(self, module: str, keyframe_every: int, keep: int = 3) -> None:
        if keyframe_every < 1:
            raise ValueError('keyframe_every must be >= 1')
        self.module = module
        self.keyframe_every = keyframe_every
        self.keep = keep
        self.seq = 0
        self.sent: 'OrderedDict[int, Dict[str, Any]]' = OrderedDict()    # seq -> state replicated
        self.since_keyframe = 0
        self.want_keyframe = False

    def next(self, state: Dict[str, Any]) -> Tuple[int, int, bytes]:
        """``(seq, base_seq, data)`` of the next replica: base_seq 0 and the whole state for a keyframe."""
        last = self.sent.get(self.seq)
        self.seq += 1
        if last is None or self.want_keyframe or self.since_keyframe + 1 >= self.keyframe_every:
            base, data = 0, encode(self.module, state)
            self.since_keyframe, self.want_keyframe = 0, False
        else:
            base, data = self.seq - 1, encode_patch(self.module, self.seq - 1, diff(last, state))
            self.since_keyframe += 1
        self.sent[self.seq] = state
        while len(self.sent) > self.keep:
            self.sent.popitem(last=False)
        return self.seq, base, data

    def final(self, state: Dict[str, Any], base_seq: int) -> bytes:
        """The state handed over at a freeze: a patch to replica ``base_seq`` if it is one of the last kept,
        else the whole state."""
        base = self.sent.get(base_seq) if base_seq else None
        return encode(self.module, state) if base is None else encode_patch(self.module, base_seq,
                                                                             diff(base, state))


class Replica:
    """A receiver's newest replicas of a module's active instance (the last ``keep``: a patch may refer to one
    replica before the newest, e.g. a freeze answered while the next replica was on its way), kept by applying
    the instance's stream."""

    def __init__(self, module: str, keep: int = 3) -> None:
        self.module = module
        self.keep = keep
        self.instance = ''
        self.states: 'OrderedDict[int, Dict[str, Any]]' = OrderedDict()      # seq -> state, oldest first

    @property
    def seq(self) -> int:
        return next(reversed(self.states)) if self.states else 0

    @property
    def state(self) -> Optional[Dict[str, Any]]:
        return self.states[self.seq] if self.states else None

    def seq_of(self, instance: str) -> int:
        """The newest replica held of ``instance`` (0: none)."""
        return self.seq if instance == self.instance else 0

    def take(self, instance: str, seq: int, base_seq: int, data: bytes) -> bool:
        """Apply one replica message; False when it cannot be (a patch to a replica not held: the next
        keyframe resets the stream). Raises :class:`StateError` for data that is not a state."""
        base, doc = decode_any(self.module, data)
        if base != base_seq:
            raise StateError(f'state of {self.module}: replica {seq} says base {base_seq}, its data {base}')
        if base == 0:
            new = doc
        elif instance == self.instance and base in self.states:
            new = patch(self.states[base], doc)
        else:
            return False
        if instance != self.instance or seq <= self.seq:        # another instance, or a restarted one
            self.states.clear()
        self.instance = instance
        self.states[seq] = new
        while len(self.states) > self.keep:
            self.states.popitem(last=False)
        return True

    def resolve(self, instance: str, data: bytes) -> Dict[str, Any]:
        """The whole state ``data`` stands for: itself, or a patch of ``instance`` applied to the replica of it
        held. Raises :class:`BaseMissing` if that replica is not held, :class:`StateError` for bad data."""
        base, doc = decode_any(self.module, data)
        if base == 0:
            return doc
        if instance != self.instance or base not in self.states:
            raise BaseMissing(f'{BASE_MISSING}: the patch is to replica {base} of {instance or "?"}, held '
                              f'{list(self.states) if instance == self.instance else "none"}')
        return patch(self.states[base], doc)

    def reset(self) -> None:
        """Forget the replicas (a state resolved from them went to a node, which may change what they share)."""
        self.instance = ''
        self.states.clear()
