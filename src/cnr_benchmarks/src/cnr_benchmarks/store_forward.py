"""Figures of cnr_store_forward on one private master (a free port): the latency the relay adds, the rate at
which a backlog drains after an outage, the rate the sender stores records at, and what fsync costs.

    /usr/bin/python3 -m cnr_benchmarks.store_forward [--config config/store_forward.yaml] [--out FILE.json]

Needs the workspace sourced (the nodes run through rosrun). Records are cnr_msgs/MergedMeasurement (68 bytes
serialized with an empty frame_id; the merger's, with frame_id map, are 71). Latency: a record's wall-clock
stamp to its arrival, relayed versus direct (the same message on the input topic), on one host, so the
difference is what the relay adds; records are published at random intervals (mean 1/rate) so that they meet
the sender's ticks at every phase.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import tempfile
import time
from typing import Any, Dict, List, Optional

from cnr_harness import RosMaster, wait_until
from cnr_params import load_yaml
from cnr_benchmarks import results
from cnr_benchmarks.core.stats import percentile
from cnr_store_forward.core.queue import DiskQueue

IN, OUT = '/sf_bench/in', '/sf_bench/out'


def fsync_cost(directory: str, records: int, size: int) -> List[Dict[str, Any]]:
    """Appending ``records`` records of ``size`` bytes: no fsync, fsync per record, per 20 records."""
    rows = []
    for name, fsync, every in (('no fsync', False, 1), ('fdatasync every record', True, 1),
                               ('fdatasync every 20 records', True, 20)):
        path = os.path.join(directory, name.replace(' ', '_'))
        q = DiskQueue(path, records + 1, 1 << 40, 4 << 20, fsync)
        data = b'x' * size
        t0 = time.perf_counter()
        for i in range(records):
            q.append(data, i)
            if (i + 1) % every == 0:
                q.sync()
        q.sync()
        took = time.perf_counter() - t0
        q.close()
        rows.append({'mode': name, 'records': records, 'us_per_record': 1e6 * took / records,
                     'records_per_s': records / took})
    return rows


class Bench:
    """The bench's rospy node on ``master``, running a sender and a receiver with ``params`` (+ changes)."""

    def __init__(self, master: RosMaster, params: Dict[str, Any], tmp: str) -> None:
        self.master = master
        self.params = params
        self.tmp = tmp
        self.runs = 0

    def configure(self, changes: Dict[str, Any]) -> str:
        self.runs += 1
        stream = f'bench{self.runs}'
        p = json.loads(json.dumps(self.params))
        p.update(stream=stream, status_rate=5.0)
        p['sender'].update(input_topic=IN, queue_dir=os.path.join(self.tmp, 'queue'), **changes)
        p['receiver'].update(output_topic=OUT, state_dir=os.path.join(self.tmp, 'state'))
        for role in ('sender', 'receiver'):
            self.master.call('setParam', f'/sf_{role}_{stream}', p)
        return stream

    def start(self, role: str, stream: str):
        return self.master.run(['rosrun', 'cnr_store_forward', role, f'__name:=sf_{role}_{stream}'],
                               f'sf_{role}_{stream}')

    def stop(self, pub, subs: List, procs: List) -> None:
        """Unregister the bench's publisher and subscribers, stop the sender and receiver processes."""
        for s in subs:
            s.unregister()
        pub.unregister()
        for p in procs:
            self.master.stop_child(p)

    def latency(self, changes: Dict[str, Any], count: int, rate: float) -> Dict[str, Any]:
        import rospy
        from cnr_msgs.msg import MergedMeasurement
        stream = self.configure(changes)
        direct: List[float] = []
        relayed: List[float] = []

        def arrival(into: List[float]):
            return lambda m: into.append(time.time() - m.header.stamp.to_sec())
        pub = rospy.Publisher(IN, MergedMeasurement, queue_size=100)
        subs = [rospy.Subscriber(IN, MergedMeasurement, arrival(direct), queue_size=None),
                rospy.Subscriber(OUT, MergedMeasurement, arrival(relayed), queue_size=None)]
        procs = [self.start('receiver', stream), self.start('sender', stream)]
        try:
            wait_until(lambda: pub.get_num_connections() == 2, 30, 'the sender subscribed', procs[1])
            # a first record, until it is relayed: the receiver's output publisher is connected
            pub.publish(MergedMeasurement(header=rospy.Header(stamp=rospy.Time.from_sec(time.time()))))
            wait_until(lambda: relayed, 30, 'the first relayed record', procs[1])
            direct.clear()
            relayed.clear()
            rng = random.Random(1)
            t = time.monotonic()
            for _ in range(count):
                pub.publish(MergedMeasurement(header=rospy.Header(stamp=rospy.Time.from_sec(time.time()))))
                t += rng.uniform(0.0, 2.0 / rate)      # random phase against the sender's ticks
                time.sleep(max(0.0, t - time.monotonic()))
            wait_until(lambda: len(relayed) >= count and len(direct) >= count, 60, 'every record relayed')
        finally:
            self.stop(pub, subs, procs)
        d, r = [1e3 * x for x in direct], [1e3 * x for x in relayed]
        return {'changes': changes, 'count': count, 'rate_hz': rate, 'direct_median_ms': statistics.median(d),
                'relayed_median_ms': statistics.median(r), 'relayed_p95_ms': percentile(r, 95),
                'relayed_max_ms': max(r), 'added_median_ms': statistics.median(r) - statistics.median(d)}

    def drain(self, changes: Dict[str, Any], count: int) -> Dict[str, Any]:
        """An outage: the receiver is stopped, ``count`` records are stored meanwhile and the sender backs off to
        ``max_backoff``; then the receiver is started again. Records/s stored and drained, and the time from
        the receiver's start to the first delivery."""
        import rospy
        from cnr_msgs.msg import MergedMeasurement, StoreForwardStatus
        stream = self.configure(changes)
        status: List[Optional[StoreForwardStatus]] = [None]
        arrived: List[float] = []
        pub = rospy.Publisher(IN, MergedMeasurement, queue_size=count)
        subs = [rospy.Subscriber(OUT, MergedMeasurement, lambda m: arrived.append(time.monotonic()), queue_size=None),
                rospy.Subscriber(f'/sf_sender_{stream}/status', StoreForwardStatus,
                                 lambda m: status.__setitem__(0, m))]
        receiver, sender = self.start('receiver', stream), self.start('sender', stream)
        procs = [receiver, sender]
        try:
            wait_until(lambda: pub.get_num_connections() == 1, 30, 'the sender subscribed', sender)
            msg = MergedMeasurement()
            pub.publish(msg)
            wait_until(lambda: arrived, 30, 'the first record relayed', sender)
            self.master.stop_child(receiver)
            procs.remove(receiver)
            t0 = time.monotonic()
            for _ in range(count):
                pub.publish(msg)
            wait_until(lambda: status[0] is not None and status[0].appended >= count + 1, 120, 'all stored', sender)
            stored = time.monotonic() - t0
            wait_until(lambda: status[0].timeouts >= 4, 60, 'the sender backed off', sender)
            arrived.clear()
            t1 = time.monotonic()
            procs.append(self.start('receiver', stream))
            wait_until(lambda: len(arrived) >= count, 600, 'the backlog drained', sender)
        finally:
            self.stop(pub, subs, procs)
        first, last = arrived[0], arrived[-1]
        return {'changes': changes, 'count': count, 'store_records_per_s_at_least': count / stored,
                'first_after_receiver_start_s': first - t1,
                'drain_records_per_s': (count - 1) / (last - first) if last > first else float('inf')}


def table(rows: List[Dict[str, Any]], keys: List[str]) -> str:
    def cell(v: Any) -> str:
        return f'{v:.1f}' if isinstance(v, float) else (json.dumps(v) if isinstance(v, dict) else str(v))
    lines = ['| ' + ' | '.join(keys) + ' |', '|' + '---|' * len(keys)]
    lines += ['| ' + ' | '.join(cell(r[k]) for k in keys) + ' |' for r in rows]
    return '\n'.join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--config', default=os.path.join(results.WS, 'config', 'store_forward.yaml'))
    ap.add_argument('--out', help='write the figures here as JSON')
    ap.add_argument('--latency-count', type=int, default=300)
    ap.add_argument('--latency-rate', type=float, default=10.0)
    ap.add_argument('--drain-count', type=int, default=3000)
    args = ap.parse_args(argv)
    params = load_yaml(args.config)
    tmp = tempfile.mkdtemp(prefix='sf-bench-')
    figures: Dict[str, Any] = {'fsync': fsync_cost(os.path.join(tmp, 'fsync'), 2000, 71)}
    print(table(figures['fsync'], ['mode', 'records', 'us_per_record', 'records_per_s']), flush=True)
    with RosMaster(log_dir=os.path.join(tmp, 'logs'), caller='/sf_bench') as master:
        os.environ['ROS_MASTER_URI'] = master.uri
        os.environ['ROS_IP'] = '127.0.0.1'
        import rospy
        rospy.init_node('sf_bench', anonymous=True, disable_signals=True)
        bench = Bench(master, params, tmp)
        figures['latency'] = [bench.latency(c, args.latency_count, args.latency_rate) for c in (
            {}, {'sync_period': 0.0}, {'fsync': False, 'sync_period': 0.0})]
        print(table(figures['latency'], ['changes', 'rate_hz', 'direct_median_ms', 'relayed_median_ms',
                                         'relayed_p95_ms', 'added_median_ms']), flush=True)
        figures['drain'] = [bench.drain(c, args.drain_count) for c in (
            {}, {'rate': 50.0, 'batch_records': 100, 'window': 1000})]
        print(table(figures['drain'], ['changes', 'count', 'store_records_per_s_at_least',
                                       'first_after_receiver_start_s', 'drain_records_per_s']), flush=True)
        rospy.signal_shutdown('bench done')
    if args.out:
        results.save_json(args.out, figures)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
