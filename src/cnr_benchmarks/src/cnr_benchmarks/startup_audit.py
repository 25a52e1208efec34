"""What a move_base start-up costs the master: XML-RPC calls by method, and the start-up time.

    /usr/bin/python3 -m cnr_benchmarks.startup_audit [--out bench_results/sim/move_base_startup.json]

A private rosmaster on a free port runs the simulator and holds move_base's parameters (loaded from
config/navigation as move_base.launch loads them); move_base itself is started with ROS_MASTER_URI
pointing at a recording XML-RPC proxy in front of that master, so every call it makes to the
master is counted. Start-up = process start until its ``move_base`` action server answers.
"""
from __future__ import annotations

import collections
import os
import threading
import time
import xmlrpc.client
from socketserver import ThreadingMixIn
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from cnr_benchmarks.cli import sim_part_parser
from cnr_benchmarks.results import WS, save_json
from cnr_harness import RosMaster, wait_until
from cnr_navigation.core.param_files import navigation_tree


PARAM_METHODS = {'getParam', 'hasParam', 'searchParam', 'setParam', 'subscribeParam', 'unsubscribeParam',
                 'deleteParam', 'getParamNames'}
REGISTER_METHODS = {'registerPublisher', 'registerSubscriber', 'registerService'}


class _Server(ThreadingMixIn, SimpleXMLRPCServer):
    daemon_threads = True


class RecordingProxy:
    """An XML-RPC server that forwards every call to a master and counts the calls by method."""

    def __init__(self, master_uri: str) -> None:
        self.master_uri = master_uri
        self.calls = collections.Counter()
        self.lock = threading.Lock()
        self.server = _Server(('127.0.0.1', 0), requestHandler=SimpleXMLRPCRequestHandler, logRequests=False,
                              allow_none=True)
        self.server.register_instance(self)
        self.uri = f'http://127.0.0.1:{self.server.server_address[1]}/'
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def _dispatch(self, method, params):
        with self.lock:
            self.calls[method] += 1
        return getattr(xmlrpc.client.ServerProxy(self.master_uri), method)(*params)

    def close(self) -> None:
        self.server.shutdown()


def load_navigation_params(master: xmlrpc.client.ServerProxy, node: str = '/move_base') -> None:
    """Set move_base's parameters as move_base.launch does (rosparam load of config/navigation/*.yaml)."""
    for name, value in navigation_tree(os.path.join(WS, 'config'), node).items():
        master.setParam('/audit', name, value)


def audit(timeout: float = 120.0) -> dict:
    master = RosMaster(use_sim_time=True, caller='/audit')
    try:
        master.roslaunch('cnr_sim', 'simulator.launch', 'real_time_factor:=1')
        load_navigation_params(xmlrpc.client.ServerProxy(master.uri))
        os.environ.update(master.env)
        import actionlib
        import rospy
        from move_base_msgs.msg import MoveBaseAction
        rospy.init_node('startup_audit', anonymous=True, disable_signals=True)
        wait_until(lambda: not rospy.Time.now().is_zero(), 60, 'simulated time from the simulator')
        proxy = RecordingProxy(master.uri)
        t0 = time.monotonic()
        move_base = master.run(['rosrun', 'cnr_navigation', 'move_base', '__name:=move_base',
                                'cmd_vel:=mobile_base/commands/velocity'], 'move_base', env={'ROS_MASTER_URI': proxy.uri})
        client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        wait_until(lambda: client.wait_for_server(rospy.Duration(0.2)), timeout, 'the move_base action server',
                   move_base)
        startup = time.monotonic() - t0
        time.sleep(1.0)                              # let calls still in flight finish (not part of the timing)
        with proxy.lock:
            calls = dict(proxy.calls)
        proxy.close()
        return dict(startup_seconds=round(startup, 3),
                    parameter_calls=sum(v for k, v in calls.items() if k in PARAM_METHODS),
                    registrations=sum(v for k, v in calls.items() if k in REGISTER_METHODS),
                    total_calls=sum(calls.values()), calls=calls)
    finally:
        master.stop()


def main() -> None:
    ap = sim_part_parser(__doc__, 'move_base_startup.json')
    args = ap.parse_args()
    result = audit()
    print(f"move_base start-up: {result['startup_seconds']:.2f} s, {result['parameter_calls']} parameter calls, "
          f"{result['registrations']} registrations, {result['total_calls']} master calls in all")
    print('  ' + ', '.join(f'{k} {v}' for k, v in sorted(result['calls'].items())))
    save_json(args.out, result)


if __name__ == '__main__':
    main()
