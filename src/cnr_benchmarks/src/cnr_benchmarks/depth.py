"""The Kinect's depth stream to move_base: its bandwidth on the wire and move_base's CPU per frame.

    /usr/bin/python3 -m cnr_benchmarks.depth [--out bench_results/sim/depth.json] [--seconds 30]

The thesis measured 3.4 Mbit/s for the Kinect data move_base consumed. The simulated TurtleBot (cnr_bringup
robot.launch: simulator, map_server, move_base; real time; the robot standing at the corridor's start, its
costmaps updating) is brought up twice on one private master: with config/ as it is (both costmaps use the
observation sources ``scan depth``) and with the depth source removed (``scan``; the camera still publishes).
In each run, after a warm-up, during ``--seconds`` of wall time:

* the bytes of ``camera/depth/points`` on the wire: a ``rospy.AnyMsg`` subscriber adds up each serialized
  message plus TCPROS's 4-byte length prefix (what one subscriber's connection carries);
* move_base's CPU time: user + system seconds of its process (psutil; pid from the slave API ``getPid``).

move_base's CPU per depth frame = (CPU with the source - CPU without) / frames. Prints one line per figure
and writes them as JSON (name, value, unit, target), as the other benchmarks of launch_scripts/bench_sim.sh.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import threading
import time
import xmlrpc.client
from typing import Dict, List, Tuple

import psutil
import yaml

from cnr_benchmarks.cli import sim_part_parser
from cnr_benchmarks.results import WS, save_json
from cnr_harness import RosMaster, wait_until

TOPIC = 'camera/depth/points'
TCPROS_PREFIX = 4          # bytes: each message on a TCPROS connection is preceded by its length


def config_without_depth(config_dir: str, out_dir: str) -> str:
    """A copy of ``config_dir`` whose costmaps use only the ``scan`` source; returns its path."""
    dst = os.path.join(out_dir, 'config')
    shutil.copytree(config_dir, dst)
    path = os.path.join(dst, 'navigation', 'costmap_common.yaml')
    with open(path) as f:
        data = yaml.safe_load(f)
    data['obstacle_layer']['observation_sources'] = 'scan'
    with open(path, 'w') as f:
        yaml.safe_dump(data, f)
    return dst


class Counter:
    """Wall-clock arrival time and wire size of every message of a topic (not deserialised)."""

    def __init__(self, rospy, topic: str) -> None:
        self.lock = threading.Lock()
        self.arrivals: List[Tuple[float, int]] = []
        self.sub = rospy.Subscriber(topic, rospy.AnyMsg, self._cb, queue_size=50)

    def _cb(self, msg) -> None:
        with self.lock:
            self.arrivals.append((time.monotonic(), len(msg._buff) + TCPROS_PREFIX))

    def between(self, t0: float, t1: float) -> List[int]:
        with self.lock:
            return [n for t, n in self.arrivals if t0 <= t < t1]


def node_pid(master: RosMaster, node: str) -> int:
    uri = master.call('lookupNode', node)
    code, msg, pid = xmlrpc.client.ServerProxy(uri).getPid('/depth_bench')
    if code != 1:
        raise RuntimeError(f'getPid of {node}: {msg}')
    return int(pid)


def run(master: RosMaster, rospy, config_dir: str, seconds: float, warmup: float) -> Dict[str, float]:
    """One bring-up: bytes and frames of the depth stream and move_base's CPU seconds over ``seconds``."""
    proc = master.roslaunch('cnr_bringup', 'robot.launch', f'config_dir:={config_dir}', 'real_time_factor:=1.0')
    counter = Counter(rospy, TOPIC)
    try:
        def move_base_up():
            assert proc.alive(), proc.output()[-3000:]
            _, subs, _ = master.call('getSystemState')
            return any(name == '/move_base/goal' for name, _ in subs)
        wait_until(move_base_up, 120, 'move_base', proc)
        wait_until(lambda: counter.between(0.0, time.monotonic() + 1.0), 60, f'messages on {TOPIC}', proc)
        move_base = psutil.Process(node_pid(master, '/move_base'))
        time.sleep(warmup)                         # costmaps filled, start-up work done (not a synchronisation)
        cpu0, t0 = move_base.cpu_times(), time.monotonic()
        time.sleep(seconds)                        # the measurement window
        cpu1, t1 = move_base.cpu_times(), time.monotonic()
        sizes = counter.between(t0, t1)
        return dict(wall=t1 - t0, frames=len(sizes), bytes=sum(sizes),
                    cpu=(cpu1.user - cpu0.user) + (cpu1.system - cpu0.system))
    finally:
        counter.sub.unregister()
        master.stop_child(proc)
        wait_until(lambda: '/move_base' not in master.node_names(), 30, 'move_base unregistered')


def main() -> None:
    ap = sim_part_parser(__doc__, 'depth.json')
    ap.add_argument('--seconds', type=float, default=30.0, help='wall seconds measured per run')
    ap.add_argument('--warmup', type=float, default=5.0, help='wall seconds before each measurement')
    args = ap.parse_args()
    config = os.path.join(WS, 'config')
    results = []

    def report(name, value, unit, target='-'):
        results.append(dict(name=name, value=round(value, 4), unit=unit, target=target))
        print(f'{name:56s} {value:10.3f} {unit:12s} (target {target})', flush=True)

    tmp = tempfile.mkdtemp(prefix='depth-bench-')
    master = RosMaster(use_sim_time=True, caller='/depth_bench')
    try:
        os.environ.update(master.env)
        import rospy
        rospy.init_node('depth_bench', anonymous=True, disable_signals=True)
        with_depth = run(master, rospy, config, args.seconds, args.warmup)
        without = run(master, rospy, config_without_depth(config, tmp), args.seconds, args.warmup)
        rospy.signal_shutdown('benchmark over')
    finally:
        master.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    w = with_depth
    report('depth stream camera/depth/points on the wire', w['bytes'] * 8 / w['wall'] / 1e6, 'Mbit/s',
           'about 3.4 (thesis)')
    report('depth stream frame rate (wall clock, real time)', w['frames'] / w['wall'], 'Hz')
    report('depth stream message size incl. TCPROS prefix', w['bytes'] / max(w['frames'], 1), 'B')
    report('move_base CPU with the depth source', 100 * w['cpu'] / w['wall'], '% of a core')
    report('move_base CPU without the depth source', 100 * without['cpu'] / without['wall'], '% of a core')
    per_frame = (w['cpu'] / w['wall'] - without['cpu'] / without['wall']) / (w['frames'] / w['wall'])
    report('move_base CPU per depth frame (both costmaps)', 1e3 * per_frame, 'ms')
    save_json(args.out, results)


if __name__ == '__main__':
    main()
