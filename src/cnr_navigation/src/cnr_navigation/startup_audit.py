"""What a move_base start-up costs the master: XML-RPC calls by method, and the start-up time.

    /usr/bin/python3 -m cnr_navigation.startup_audit [--out bench_results/move_base_startup.json]

A private rosmaster on a free port runs the simulator and holds move_base's parameters (loaded from
config/navigation as move_base.launch loads them); move_base itself is started with ROS_MASTER_URI
pointing at a recording XML-RPC proxy in front of that master, so every call it makes to the
master is counted. Start-up = process start until its ``move_base`` action server answers.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import signal
import socket
import subprocess
import threading
import time
import xmlrpc.client
from socketserver import ThreadingMixIn
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

import yaml

WS = os.path.abspath(os.path.join(os.path.dirname(__file__), '..', '..', '..', '..'))
NAV_FILES = [('costmap_common.yaml', 'global_costmap'), ('costmap_common.yaml', 'local_costmap'),
             ('local_costmap.yaml', ''), ('global_costmap.yaml', ''), ('dwa_local_planner.yaml', ''),
             ('global_planner.yaml', ''), ('move_base.yaml', '')]

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


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def load_navigation_params(master: xmlrpc.client.ServerProxy, node: str = '/move_base',
                           controller_frequency: float = 5.0) -> None:
    """Set move_base's parameters as move_base.launch does (rosparam load of config/navigation/*.yaml)."""
    for name, ns in NAV_FILES:
        with open(os.path.join(WS, 'config', 'navigation', name)) as f:
            data = yaml.safe_load(f) or {}
        for key, value in data.items():
            master.setParam('/audit', '/'.join(p for p in (node, ns, key) if p), value)
    master.setParam('/audit', f'{node}/controller_frequency', controller_frequency)


def audit(timeout: float = 120.0) -> dict:
    port = _free_port()
    uri = f'http://127.0.0.1:{port}/'
    env = dict(os.environ, ROS_MASTER_URI=uri, ROS_IP='127.0.0.1')
    procs = [subprocess.Popen(['rosmaster', '--core', '-p', str(port)], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        master = xmlrpc.client.ServerProxy(uri)
        deadline = time.monotonic() + 30
        while True:
            try:
                master.getSystemState('/audit')
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError('rosmaster did not start')
                time.sleep(0.1)
        master.setParam('/audit', '/use_sim_time', True)
        procs.append(subprocess.Popen(['roslaunch', 'cnr_sim', 'simulator.launch', 'real_time_factor:=1'], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        load_navigation_params(master)
        os.environ.update(env)
        import actionlib
        import rospy
        from move_base_msgs.msg import MoveBaseAction
        rospy.init_node('startup_audit', anonymous=True, disable_signals=True)
        while rospy.Time.now().is_zero():
            time.sleep(0.05)
        proxy = RecordingProxy(uri)
        node_env = dict(env, ROS_MASTER_URI=proxy.uri)
        t0 = time.monotonic()
        procs.append(subprocess.Popen(['rosrun', 'cnr_navigation', 'move_base', '__name:=move_base',
                                       'cmd_vel:=mobile_base/commands/velocity'], env=node_env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        client = actionlib.SimpleActionClient('move_base', MoveBaseAction)
        while not client.wait_for_server(rospy.Duration(0.2)):
            if time.monotonic() - t0 > timeout:
                raise RuntimeError('move_base did not become ready')
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
        for p in reversed(procs):
            try:
                os.killpg(p.pid, signal.SIGINT)
                p.wait(15)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--out', default=os.path.join(WS, 'bench_results', 'move_base_startup.json'))
    args = ap.parse_args()
    result = audit()
    print(f"move_base start-up: {result['startup_seconds']:.2f} s, {result['parameter_calls']} parameter calls, "
          f"{result['registrations']} registrations, {result['total_calls']} master calls in all")
    print('  ' + ', '.join(f'{k} {v}' for k, v in sorted(result['calls'].items())))
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, 'w') as f:
        json.dump(result, f, indent=1)
    print(f'wrote {args.out}')


if __name__ == '__main__':
    main()
