"""What one poll of the local master costs the bridge and the master (CPU time of both processes).

    /usr/bin/python3 -m cnr_benchmarks.bridge_poll [--nodes 30] [--topics-per-node 4] [--polls 200] [--rate 10]

A master on a free port holds a graph like the robot's (``--nodes`` nodes, each publishing ``--topics-per-node``
topics with a subscriber and one service); the bridge's :class:`multimaster_bridge.node.MasterClient` polls it
at ``--rate`` Hz (a full refresh once a second, as the bridge does), as it is and as two simpler clients
(:class:`AsBefore`, :class:`ParsedEachPoll`, the baselines), twice each in turn. Prints ms of CPU per poll and the CPU
share at the rate.
"""
from __future__ import annotations

import argparse
import sys
import time
import xmlrpc.client
from typing import Callable, List, Optional

import psutil

from cnr_harness import RosMaster
from multimaster_bridge.core import sync
from multimaster_bridge.node import MasterClient


class AsBefore(MasterClient):
    """Baseline: a new connection (and a new master thread) for every call, getSystemState and getTopicTypes on
    every poll."""

    def _proxy(self) -> xmlrpc.client.ServerProxy:
        return xmlrpc.client.ServerProxy(self.uri)

    def system_state(self, previous, refresh):
        multi = xmlrpc.client.MultiCall(self._proxy())
        multi.getSystemState(self.caller_id)
        multi.getTopicTypes(self.caller_id)
        (_c1, _, state), (c2, _, types) = tuple(multi())
        return sync.Snapshot.from_system_state(state, types if c2 == 1 else [])


class ParsedEachPoll(MasterClient):
    """Baseline: a kept-alive connection, but every answer gzip-compressed by the master and parsed by the
    bridge, even when it is the same as the last one."""

    def _proxy(self) -> xmlrpc.client.ServerProxy:
        if self._server is None:
            self._server = xmlrpc.client.ServerProxy(self.uri)
        return self._server


def fill(master: RosMaster, nodes: int, per_node: int) -> None:
    """Registrations of made-up nodes (their URIs are never called: nobody subscribes to what they publish)."""
    px = xmlrpc.client.ServerProxy(master.uri)
    for i in range(nodes):
        api, nxt = f'http://127.0.0.1:{10000 + i}/', (i + 1) % nodes
        for j in range(per_node):
            px.registerPublisher(f'/node{i}', f'/topic{i}_{j}', 'std_msgs/String', api)
            px.registerSubscriber(f'/node{nxt}', f'/topic{i}_{j}', 'std_msgs/String', f'http://127.0.0.1:{10000 + nxt}/')
        px.registerService(f'/node{i}', f'/node{i}/get_loggers', f'rosrpc://127.0.0.1:{20000 + i}', api)


def measure(master_proc: psutil.Process, make: Callable[[], MasterClient], polls: int, rate: float) -> List[float]:
    me = psutil.Process()
    client = make()
    m0, c0 = sum(master_proc.cpu_times()[:2]), sum(me.cpu_times()[:2])
    snap = None
    for k in range(polls):
        snap = client.snapshot(snap, refresh_nodes=(k % max(1, int(rate)) == 0))
        time.sleep(1.0 / rate)
    return [1000.0 * (sum(master_proc.cpu_times()[:2]) - m0) / polls, 1000.0 * (sum(me.cpu_times()[:2]) - c0) / polls]


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='bridge_poll', description=__doc__.split('\n')[0])
    ap.add_argument('--nodes', type=int, default=30)
    ap.add_argument('--topics-per-node', type=int, default=4)
    ap.add_argument('--polls', type=int, default=200)
    ap.add_argument('--rate', type=float, default=10.0, help='Hz (the bridge\'s poll_rate)')
    ap.add_argument('--stock-master', action='store_true',
                    help='rosmaster as it is, not the multi-master hosts\' cnr_harness.rosmaster')
    args = ap.parse_args(argv)
    with RosMaster(multi_master=not args.stock_master) as master:
        fill(master, args.nodes, args.topics_per_node)
        proc = psutil.Process(master.proc.pid)
        print(f'master with {args.nodes} nodes, {args.nodes * args.topics_per_node} topics; {args.polls} polls at '
              f'{args.rate:g} Hz each', flush=True)
        for _ in range(2):
            for label, make in (('baseline: a new connection per call, types every poll ', AsBefore),
                                ('baseline: a kept-alive connection, types when new     ', ParsedEachPoll),
                                ('the bridge (no gzip, an unchanged answer not parsed)   ', MasterClient)):
                m, c = measure(proc, lambda: make(master.uri, '/bridge'), args.polls, args.rate)
                print(f'{label}: CPU per poll: master {m:.2f} ms, bridge {c:.2f} ms; at {args.rate:g} Hz '
                      f'{(m + c) * args.rate / 1000.0:.3f} CPU', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
