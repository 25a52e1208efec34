"""Bridge-to-bridge datagrams: JSON, zlib, authenticated with HMAC-SHA256 over a shared secret (ROS-free).

Every datagram carries the sender's name, a random session id and a sequence number; a receiver accepts a
datagram only if its HMAC verifies and its sequence number is newer than the last one seen from that
session (replays are rejected). Kinds: ``hb`` (heartbeat with NTP-style echo), ``state`` (full registration
state), ``req`` (ask for a state).
"""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import zlib
from dataclasses import dataclass
from typing import Any, Dict, Optional, Tuple

MAGIC = b'CNRB1'
MAC_LEN = 32


class ProtocolError(ValueError):
    pass


def encode(secret: bytes, message: Dict[str, Any]) -> bytes:
    body = zlib.compress(json.dumps(message, separators=(',', ':')).encode())
    mac = hmac.new(secret, MAGIC + body, hashlib.sha256).digest()
    return MAGIC + mac + body


def decode(secret: bytes, datagram: bytes) -> Dict[str, Any]:
    if not datagram.startswith(MAGIC) or len(datagram) < len(MAGIC) + MAC_LEN:
        raise ProtocolError('not a bridge datagram')
    mac = datagram[len(MAGIC):len(MAGIC) + MAC_LEN]
    body = datagram[len(MAGIC) + MAC_LEN:]
    if not hmac.compare_digest(mac, hmac.new(secret, MAGIC + body, hashlib.sha256).digest()):
        raise ProtocolError('bad HMAC (wrong secret?)')
    try:
        msg = json.loads(zlib.decompress(body).decode())
    except (zlib.error, ValueError) as exc:
        raise ProtocolError(f'undecodable body: {exc}') from None
    for key in ('from', 'session', 'seq', 'kind'):
        if key not in msg:
            raise ProtocolError(f'missing field {key!r}')
    return msg


class ReplayGuard:
    """Accepts increasing sequence numbers per (sender, session)."""

    def __init__(self) -> None:
        self._last: Dict[Tuple[str, str], int] = {}

    def accept(self, msg: Dict[str, Any]) -> bool:
        key = (msg['from'], msg['session'])
        if msg['seq'] <= self._last.get(key, -1):
            return False
        self._last[key] = msg['seq']
        return True


def new_session() -> str:
    return os.urandom(8).hex()
