"""A module instance's launch, resolved by the agent: the node's command line, environment and parameters.

The agent used to start every instance as ``cnr_launch <package> <file> <module>:=true ...``: a launch parent per
instance that imports roslaunch, parses the launch file, sets the parameters and starts the one node. On the
robot, whose modules share a third of a core, that parent costs more CPU than the node's own start-up
(``import roslaunch`` alone: 0.63 CPU-s here, ``import rospy`` 0.40) and then polls its child for as long as it
runs (all parents together: 0.027 CPU of the robot's 0.33 in the hot bench). So the agent loads the
launch once with roslaunch's own loader (same substitutions, includes, ``rosparam`` files, ``env`` and remaps as
``roslaunch``) and starts each instance itself: the parameters in one XML-RPC multicall to the master, then the
node's process, exactly as roslaunch would have run it. The launch is resolved again for every instance (as a
``roslaunch`` per instance would read it: a configuration edited since is what the next instance gets), without
roscore.xml (its ``rosversion`` calls were two thirds of the 0.2 s a resolution took).

An instance is one node: a launch that gives a module no node or several is a configuration error.
"""
from __future__ import annotations

import os
import xmlrpc.client
from dataclasses import dataclass
from typing import Any, Dict, List, Sequence

from cnr_harness import master_proxy

CALLER_ID = '/migration_agent'


class LaunchError(Exception):
    """The launch cannot be resolved into one node (message names the launch and the module)."""


@dataclass(frozen=True)
class NodeLaunch:
    module: str
    node: str                       # the node's resolved name, e.g. /move_base
    argv: List[str]                 # the node's command line (its executable, args, remaps, __name)
    env: Dict[str, str]             # the node's environment (ROS_MASTER_URI, ROS_NAMESPACE, the launch's env)
    params: Dict[str, Any]          # parameter key -> value, set on the master before each start
    clear: List[str]                # parameter namespaces cleared first (``clear_params``)

    def set_params(self, master_uri: str, timeout: float) -> None:
        """Clear and set the parameters, each in one multicall (as roslaunch does); OSError / LaunchError."""
        proxy = master_proxy(master_uri, timeout)
        for batch, what in ((self.clear, 'clear'), (sorted(self.params), 'set')):
            if not batch:
                continue
            multi = xmlrpc.client.MultiCall(proxy)
            for key in batch:
                if what == 'clear':
                    multi.deleteParam(CALLER_ID, key)
                else:
                    multi.setParam(CALLER_ID, key, self.params[key])
            for key, (code, msg, _) in zip(batch, multi()):
                if code != 1 and what == 'set':
                    raise LaunchError(f'{self.module}: the master refused parameter {key}: {msg}')


def resolve(package: str, launch_file: str, module: str, args: Sequence[str], master_uri: str) -> NodeLaunch:
    """The one node that ``<package> <launch_file> <args...>`` (``name:=value``) launches for ``module``."""
    import roslaunch.config
    import roslaunch.core
    import roslaunch.loader
    import roslaunch.node_args
    import roslaunch.rlutil
    import roslaunch.xmlloader
    from roslaunch.core import RLException
    try:
        files = roslaunch.rlutil.resolve_launch_arguments([package, launch_file])
        config = roslaunch.config.ROSLaunchConfig()
        roslaunch.xmlloader.XmlLoader().load(files[0], config, argv=list(args), verbose=False)
        config.assign_machines()
    except (RLException, roslaunch.xmlloader.XmlParseException, roslaunch.loader.LoadException,
            IndexError) as exc:
        raise LaunchError(f'{package} {launch_file} {module}:=true: {exc}') from exc
    if len(config.nodes) != 1:
        names = ', '.join(n.name for n in config.nodes) or 'none'
        raise LaunchError(f'{package} {launch_file} {module}:=true launches {len(config.nodes)} nodes ({names}); '
                          f'an instance is one node')
    node = config.nodes[0]
    try:
        argv = roslaunch.node_args.create_local_process_args(node, node.machine)
    except (RLException, ValueError) as exc:
        raise LaunchError(f'{package} {launch_file} {module}:=true: {exc}') from exc
    env = roslaunch.core.setup_env(node, node.machine, master_uri, env=os.environ)
    params = {p.key: p.value for p in config.params.values()}
    name = node.namespace.rstrip('/') + '/' + node.name
    return NodeLaunch(module=module, node=name, argv=argv, env=dict(env), params=params,
                      clear=list(config.clear_params))
