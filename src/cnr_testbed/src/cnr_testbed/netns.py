"""Network namespaces and TUN devices (Linux, root): the few system calls the testbed needs."""
from __future__ import annotations

import ctypes
import fcntl
import os
import struct
import subprocess
import contextlib
from typing import Iterator, List

CLONE_NEWNET = 0x40000000
TUNSETIFF = 0x400454CA
IFF_TUN = 0x0001
IFF_NO_PI = 0x1000
NETNS_DIR = '/var/run/netns'

_libc = ctypes.CDLL(None, use_errno=True)


def _setns(fd: int) -> None:
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f'setns: {os.strerror(err)}')


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run ``ip`` (iproute2); raises RuntimeError with its message on failure."""
    r = subprocess.run(['ip', *args], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip() or r.stdout.strip()}")
    return r


def namespaces() -> List[str]:
    try:
        return sorted(os.listdir(NETNS_DIR))
    except FileNotFoundError:
        return []


def add_namespace(name: str) -> None:
    ip('netns', 'add', name)
    ip('-n', name, 'link', 'set', 'lo', 'up')


def has_sysctl(key: str) -> bool:
    """Whether this kernel has the setting ``key`` (e.g. ``net.ipv4.tcp_rto_max_ms``: Linux 6.15 and later)."""
    return os.path.exists(os.path.join('/proc/sys', *key.split('.')))


def set_sysctl(namespace: str, key: str, value: int) -> None:
    """Write the network setting ``key`` (e.g. ``net.ipv4.tcp_thin_linear_timeouts``) of ``namespace``'s kernel
    stack: /proc/sys/net opened from inside the namespace is its own."""
    path = os.path.join('/proc/sys', *key.split('.'))
    with inside(namespace):
        try:
            with open(path, 'w') as f:
                f.write(str(value))
        except OSError as exc:
            raise RuntimeError(f'sysctl {key} = {value} in the namespace {namespace}: {exc.strerror}') from None


def delete_namespace(name: str) -> None:
    if name in namespaces():
        ip('netns', 'delete', name, check=False)


@contextlib.contextmanager
def inside(namespace: str) -> Iterator[None]:
    """Run the calling thread inside ``namespace``; sockets created meanwhile stay in it."""
    own = os.open('/proc/self/ns/net', os.O_RDONLY)
    target = os.open(os.path.join(NETNS_DIR, namespace), os.O_RDONLY)
    try:
        _setns(target)
        try:
            yield
        finally:
            _setns(own)
    finally:
        os.close(own)
        os.close(target)


def open_tun(namespace: str, device: str) -> int:
    """Create a TUN device (IFF_TUN | IFF_NO_PI) inside ``namespace``; returns its fd (non-blocking).

    The device lives as long as the fd: it vanishes when the owning process exits, however it exits.
    """
    with inside(namespace):
        fd = os.open('/dev/net/tun', os.O_RDWR | os.O_NONBLOCK)
        fcntl.ioctl(fd, TUNSETIFF, struct.pack('16sH', device.encode(), IFF_TUN | IFF_NO_PI))
    return fd


def configure(namespace: str, device: str, address: str, peer: str, prefix: int, mtu: int) -> None:
    ip('-n', namespace, 'addr', 'add', f'{address}/32', 'peer', f'{peer}/32', 'dev', device)
    ip('-n', namespace, 'link', 'set', device, 'mtu', str(mtu), 'up')
