"""The bridge's configuration, validated (ROS-free)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import List, Tuple

from cnr_params import ConfigError, Section

from multimaster_bridge.core.sync import Filter


@dataclass
class Peer:
    name: str
    host: str
    port: int


@dataclass
class BridgeConfig:
    name: str
    listen: Tuple[str, int]
    peers: List[Peer]
    secret: bytes
    topics: Filter
    services: Filter
    in_order: Filter          # topics whose publishers are never reconnected by a new URI spelling
    heartbeat_rate: float
    loss_timeout: float
    poll_rate: float
    quality_rate: float
    nice: int                 # the bridge's CPU priority (cnr_runtime.priority)
    extra: dict = field(default_factory=dict)


def parse_address(section: Section, key: str, default_host: str = '') -> Tuple[str, int]:
    text = section.string(key)
    host, sep, port = text.rpartition(':')
    if not sep:
        host, port = default_host, text
    try:
        number = int(port)
    except ValueError:
        raise section.error(key, f"expected host:port, got '{text}'") from None
    if not 0 < number < 65536:
        raise section.error(key, f'port out of range in {text!r}')
    if not host:
        raise section.error(key, f"expected host:port, got '{text}'")
    return host, number


def _globs(section: Section, key: str) -> List[str]:
    value = section.raw(key)
    if value is None:
        return []
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise section.error(key, f'expected a list of glob strings, got {value!r}')
    return value


def parse(section: Section) -> BridgeConfig:
    """Raises ConfigError naming the field for anything missing or wrong."""
    name = section.string('name').strip('/')
    if not name or '/' in name:
        raise section.error('name', f"expected a plain name like 'robot', got {section.raw('name')!r}")
    listen = parse_address(section, 'listen')
    peers = []
    for p in section.sections('peers'):
        pname = p.string('name').strip('/')
        if not pname or '/' in pname or pname == name:
            raise p.error('name', f'bad peer name {p.raw("name")!r}')
        host, port = parse_address(p, 'address')
        peers.append(Peer(pname, host, port))
    if not peers:
        raise section.error('peers', 'no peers configured (a list of {name, address})')
    if len({p.name for p in peers}) != len(peers):
        raise section.error('peers', 'peer names must be unique')
    if 'secret_file' not in section and 'secret' not in section:
        raise section.error('secret', 'missing (set ~secret or ~secret_file)')
    secret = section.string('secret') if 'secret' in section else ''
    if 'secret_file' in section:
        path = section.string('secret_file')
        try:
            with open(os.path.expanduser(path), 'rb') as stream:
                secret = stream.read().strip().decode('utf-8', 'replace')
        except OSError as exc:
            raise section.error('secret_file', f'cannot read {path}: {exc.strerror}') from None
    if len(secret) < 8:
        raise section.error('secret', 'a shared secret of at least 8 characters is required '
                            '(set ~secret or ~secret_file)')
    cfg = BridgeConfig(
        name=name, listen=listen, peers=peers, secret=secret.encode(),
        topics=Filter(_globs(section, 'allow_topics'), _globs(section, 'deny_topics')),
        services=Filter(_globs(section, 'allow_services'), _globs(section, 'deny_services')),
        in_order=Filter(_globs(section, 'in_order_topics')),
        heartbeat_rate=section.number('heartbeat_rate', minimum=1.0, maximum=50.0),
        loss_timeout=section.number('loss_timeout', positive=True),
        poll_rate=section.number('poll_rate', minimum=0.05, maximum=100.0),
        quality_rate=section.number('quality_rate', positive=True),
        nice=section.integer('nice', minimum=-20, maximum=19))
    if cfg.loss_timeout < 3.0 / cfg.heartbeat_rate:
        raise section.error('loss_timeout', f'must cover at least 3 heartbeats ({3.0 / cfg.heartbeat_rate:.2f} s)')
    return cfg


__all__ = ['BridgeConfig', 'ConfigError', 'Peer', 'parse']
