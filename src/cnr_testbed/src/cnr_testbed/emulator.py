"""The user-space link emulator process: owns one TUN device in each namespace and forwards IP packets
between them through two :class:`cnr_testbed.core.link.LinkDirection` schedulers; a unix control socket
(JSON lines) changes conditions live and reports status.

Started by ``testbed.sh up`` (``python3 -m cnr_testbed.emulator CONFIG``) as a supervisor process that
forks the forwarding child: whatever way the child ends (signal, crash, SIGKILL), the supervisor removes the
namespaces, the socket and the pid file, so nothing is left behind.
"""
from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import sys
import time
from typing import Dict

from cnr_testbed.core.config import TestbedConfig, load_testbed
from cnr_testbed.core.link import Conditions, LinkDirection
from cnr_testbed import netns

RUN_DIR = '/run/cnr_testbed'


def socket_path(name: str) -> str:
    return os.path.join(RUN_DIR, f'{name}.sock')


def pid_path(name: str) -> str:
    return os.path.join(RUN_DIR, f'{name}.pid')


class Forwarder:
    def __init__(self, cfg: TestbedConfig) -> None:
        self.cfg = cfg
        self.fd_r = netns.open_tun(cfg.robot_ns, cfg.robot_dev)
        self.fd_c = netns.open_tun(cfg.cloud_ns, cfg.cloud_dev)
        netns.configure(cfg.robot_ns, cfg.robot_dev, cfg.robot_address, cfg.cloud_address, cfg.prefix, cfg.mtu)
        netns.configure(cfg.cloud_ns, cfg.cloud_dev, cfg.cloud_address, cfg.robot_address, cfg.prefix, cfg.mtu)
        self.links: Dict[str, LinkDirection] = {'up': LinkDirection(cfg.up), 'down': LinkDirection(cfg.down)}
        self.started = time.monotonic()
        path = socket_path(cfg.name)
        if os.path.exists(path):
            os.unlink(path)
        self.ctl = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.ctl.bind(path)
        self.ctl.listen(8)
        self.ctl.setblocking(False)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.fd_r, selectors.EVENT_READ, 'up')        # robot -> cloud
        self.sel.register(self.fd_c, selectors.EVENT_READ, 'down')      # cloud -> robot
        self.sel.register(self.ctl, selectors.EVENT_READ, 'accept')
        self.running = True

    def status(self) -> Dict:
        return dict(name=self.cfg.name, pid=os.getppid(), emulator_pid=os.getpid(),
                    uptime=round(time.monotonic() - self.started, 3),
                    robot=dict(namespace=self.cfg.robot_ns, device=self.cfg.robot_dev, address=self.cfg.robot_address),
                    cloud=dict(namespace=self.cfg.cloud_ns, device=self.cfg.cloud_dev, address=self.cfg.cloud_address),
                    up=self.links['up'].status(), down=self.links['down'].status())

    def command(self, req: Dict) -> Dict:
        cmd = req.get('cmd')
        if cmd == 'status':
            return dict(ok=True, status=self.status())
        if cmd == 'set':
            direction = req.get('dir', 'both')
            if direction not in ('up', 'down', 'both'):
                return dict(ok=False, error=f"dir must be up, down or both, got {direction!r}")
            changes = req.get('conditions', {})
            try:
                new = {d: self.links[d].conditions.updated(**changes)
                       for d in (('up', 'down') if direction == 'both' else (direction,))}
            except (ValueError, TypeError) as exc:
                return dict(ok=False, error=str(exc))
            for d, c in new.items():
                self.links[d].set(c)
            return dict(ok=True, status=self.status())
        if cmd == 'stop':
            self.running = False
            return dict(ok=True)
        return dict(ok=False, error=f'unknown command {cmd!r} (status, set, stop)')

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(2.0)
        try:
            data = b''
            while not data.endswith(b'\n'):
                chunk = conn.recv(65536)
                if not chunk:
                    break
                data += chunk
            try:
                reply = self.command(json.loads(data.decode() or '{}'))
            except json.JSONDecodeError as exc:
                reply = dict(ok=False, error=f'bad request: {exc}')
            conn.sendall((json.dumps(reply) + '\n').encode())
        except OSError:
            pass
        finally:
            conn.close()

    def run(self) -> None:
        out_fd = {'up': self.fd_c, 'down': self.fd_r}
        while self.running:
            now = time.monotonic()
            dues = [t for t in (self.links['up'].next_due(), self.links['down'].next_due()) if t is not None]
            timeout = max(0.0, min(dues) - now) if dues else 0.5
            # epoll rounds its timeout up to whole milliseconds: wake up early and finish the last
            # 1.5 ms in short sleeps, still polling the devices, so releases are sub-millisecond exact
            events = self.sel.select(max(0.0, timeout - 0.0015) if timeout > 0.0015 else 0)
            if not events and 0 < timeout <= 0.0015:
                time.sleep(min(timeout, 0.0002))
            for key, _ in events:
                if key.data == 'accept':
                    try:
                        conn, _ = self.ctl.accept()
                    except BlockingIOError:
                        continue
                    conn.setblocking(True)
                    self._serve(conn)
                    continue
                link = self.links[key.data]
                for _ in range(256):                  # drain what is queued on the device
                    try:
                        packet = os.read(key.fd, 65536)
                    except (BlockingIOError, InterruptedError):
                        break
                    link.offer(packet, time.monotonic())
            now = time.monotonic()
            for d, link in self.links.items():
                for packet in link.due(now):
                    try:
                        os.write(out_fd[d], packet)
                    except OSError:
                        pass                          # the kernel refused it (e.g. no route): dropped


def cleanup(cfg: TestbedConfig) -> None:
    for ns in (cfg.robot_ns, cfg.cloud_ns):
        netns.delete_namespace(ns)
    for path in (socket_path(cfg.name), pid_path(cfg.name)):
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass


def supervise(cfg: TestbedConfig) -> int:
    """Fork the forwarder; remove everything when it ends, however it ends."""
    os.makedirs(RUN_DIR, exist_ok=True)
    with open(pid_path(cfg.name), 'w') as f:
        f.write(str(os.getpid()))
    child = os.fork()
    if child == 0:
        signal.signal(signal.SIGINT, signal.SIG_IGN)        # the supervisor forwards TERM
        signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
        code = 0
        try:
            os.setpriority(os.PRIO_PROCESS, 0, cfg.emulator_nice)   # the link is no host's CPU consumer
            Forwarder(cfg).run()
        except SystemExit:
            pass
        except Exception as exc:                            # reported, then the supervisor cleans up
            print(f'link emulator: {exc}', file=sys.stderr, flush=True)
            code = 1
        os._exit(code)

    def forward(signum, _frame):
        try:
            os.kill(child, signal.SIGTERM)
        except ProcessLookupError:
            pass
    signal.signal(signal.SIGTERM, forward)
    signal.signal(signal.SIGINT, forward)
    signal.signal(signal.SIGHUP, forward)
    while True:
        try:
            _, status = os.waitpid(child, 0)
            break
        except InterruptedError:
            continue
    cleanup(cfg)
    return os.waitstatus_to_exitcode(status) if hasattr(os, 'waitstatus_to_exitcode') else 0


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description='user-space link emulator (started by testbed.sh up)')
    ap.add_argument('config')
    ap.add_argument('--set', action='append', default=[], metavar='KEY=VALUE', help='override testbed.<KEY>')
    args = ap.parse_args()
    overrides = dict(kv.split('=', 1) for kv in args.set)
    cfg = load_testbed(args.config, overrides)
    sys.exit(supervise(cfg))


if __name__ == '__main__':
    main()
