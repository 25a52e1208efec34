"""Which network interface carries the traffic to the peer (C_bw is measured there).

Order: a configured interface name wins; a peer address that is loopback or one of this host's own
addresses → the loopback interface; else a point-to-point interface whose remote end is the peer (a TUN,
PPP or VPN device: its own address has a /32 mask, so no subnet contains the peer — the testbed's devices);
else the interface whose IPv4 subnet contains the peer's address (the longest prefix if several); else the
default-gateway interface; else none.

The interface table comes from netifaces (:func:`netifaces_table`), or from a plain dict in tests.
"""
from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

# interface -> [(IPv4 address, netmask)] or [(IPv4 address, netmask, point-to-point peer address)]
Table = Dict[str, List[Tuple[str, ...]]]


@dataclass
class Choice:
    interface: str     # '' when nothing fits
    reason: str        # 'configured' | 'loopback' | 'local address' | 'point-to-point' | 'subnet' |
                       # 'default gateway' | 'none'


def netifaces_table(netifaces_module) -> Tuple[Table, Optional[str]]:
    """(interface table, default-gateway interface) read through ``netifaces`` (pass the module)."""
    table: Table = {}
    af_inet = netifaces_module.AF_INET
    for name in netifaces_module.interfaces():
        entries = netifaces_module.ifaddresses(name).get(af_inet, [])
        table[name] = [(e['addr'], e.get('netmask', '255.255.255.255'))
                       + ((e['peer'],) if e.get('peer') and e['peer'] != e['addr'] else ())
                       for e in entries if 'addr' in e]
    default = netifaces_module.gateways().get('default', {}).get(af_inet)
    return table, (default[1] if default else None)


def _same(address: str, peer: ipaddress.IPv4Address) -> bool:
    try:
        return ipaddress.IPv4Address(address) == peer
    except ValueError:
        return False


def choose_interface(peer_address: str, table: Table, default_interface: Optional[str],
                     configured: str = '') -> Choice:
    """The interface towards ``peer_address`` (an IPv4 address).

    Args:
        peer_address: the peer's IPv4 address (already resolved).
        table: interface -> [(address, netmask)] or [(address, netmask, point-to-point peer)].
        default_interface: the default-gateway interface, if any.
        configured: an interface name from the configuration ('' for automatic).
    """
    if configured:
        return Choice(configured, 'configured')
    try:
        peer = ipaddress.IPv4Address(peer_address)
    except ValueError:
        peer = None
    loopback = next((n for n, addrs in table.items()
                     if any(ipaddress.IPv4Address(e[0]).is_loopback for e in addrs)), None)
    if peer is not None:
        if peer.is_loopback and loopback:
            return Choice(loopback, 'loopback')
        if loopback and any(ipaddress.IPv4Address(e[0]) == peer for addrs in table.values() for e in addrs):
            return Choice(loopback, 'local address')
        for name, addrs in table.items():
            if any(len(e) > 2 and _same(e[2], peer) for e in addrs):
                return Choice(name, 'point-to-point')
        best: Optional[Tuple[int, str]] = None
        for name, addrs in table.items():
            for addr, mask, *_ in addrs:
                try:
                    net = ipaddress.IPv4Network(f'{addr}/{mask}', strict=False)
                except ValueError:
                    continue
                if peer in net and (best is None or net.prefixlen > best[0]):
                    best = (net.prefixlen, name)
        if best is not None:
            return Choice(best[1], 'subnet')
    if default_interface:
        return Choice(default_interface, 'default gateway')
    return Choice('', 'none')
