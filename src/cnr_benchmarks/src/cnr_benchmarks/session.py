"""The two-host task session the control, campaign and local-vs-remote experiments run (``two_host_mission
--task-plan``), and the configuration copy that caps the robot's CPU at another slowdown."""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from typing import Dict, List, Optional

import yaml

from cnr_benchmarks import report
from cnr_params.files import write_atomic


def two_host_argv(location: str, report_dir: str, port: int, cfg_dir: Optional[str] = None) -> Optional[List[str]]:
    """The two_host_mission command for the location's scenario with every module on the robot at the start
    (the nodes' configuration from ``cfg_dir``, default the workspace's config/); None (the scenario's problem
    printed in one line) when check_scenario refuses it."""
    cfg_dir = cfg_dir or os.path.join(report.WS, 'config')
    scenario = os.path.join(cfg_dir, 'scenarios', f'{location}.yaml')
    line = subprocess.run(['rosrun', 'cnr_mission', 'check_scenario', scenario], capture_output=True, text=True)
    if line.returncode != 0:
        print(line.stderr.strip(), file=sys.stderr)
        return None
    _name, map_file, x, y, a = line.stdout.split()
    return ['rosrun', 'cnr_mission', 'two_host_mission', '--config-dir', cfg_dir, '--scenario', scenario,
            '--map', map_file, '--start', x, y, a, '--placement', 'all_robot', '--report-dir', report_dir,
            '--port', str(port)]


def run_session(args: argparse.Namespace, plan: Dict, results: str, training_dir: str, control_values: str,
                scratch: Optional[str] = None, cfg_dir: Optional[str] = None) -> int:
    """Write the plan and run the two-host task session over it in ``scratch`` (default ``args.scratch``; its
    output passes through), its rows appended to ``results``."""
    scratch = scratch or args.scratch
    cfg_dir = cfg_dir or getattr(args, 'cfg_dir', None)
    os.makedirs(scratch, exist_ok=True)
    plan_path = os.path.join(scratch, 'plan.yaml')
    write_atomic(plan_path, yaml.safe_dump(plan, sort_keys=False))
    session = os.path.join(scratch, 'session')
    report.move_aside(session)
    argv = two_host_argv(plan['location'], session, args.port, cfg_dir)
    if argv is None:
        return 2
    argv += ['--task-plan', plan_path, '--task-results', results, '--training-dir', training_dir,
             '--control-values', control_values]
    report.progress(f'[campaign] {len(plan["runs"])} runs of {plan["task"]}@{plan["location"]}; rows in {results}')
    return report.call(argv)


def slowdown_dir(out: str, slowdown: float) -> str:
    return os.path.join(out, f'slowdown_{slowdown:g}')


def copy_config(dst: str, src: Optional[str] = None) -> str:
    """``dst``, a fresh copy of ``src`` (default the workspace's config/); a copy given as its own source is kept."""
    import shutil
    src = os.path.abspath(src or os.path.join(report.WS, 'config'))
    if src != os.path.abspath(dst):
        if os.path.exists(dst):
            shutil.rmtree(dst)
        shutil.copytree(src, dst)
    return dst


def slowdown_config(out: str, slowdown: float, src: Optional[str] = None) -> str:
    """A copy of ``src`` (default the workspace's config/) whose testbed.yaml caps the robot at 1/``slowdown`` CPU
    (the thesis's "different local CPU frequency"); rewritten on every run so it follows the configuration."""
    dst = copy_config(os.path.join(slowdown_dir(out, slowdown), 'config'), src)
    set_values(os.path.join(dst, 'testbed.yaml'),
               {'testbed': {'robot_cpu': {'enabled': True, 'slowdown': slowdown}}}, 'slowdown_config')
    return dst


TASK_OVERLAY = 'task_experiments.yaml'      # in config/: what the task experiments change in their copy


def task_config(scratch: str, slowdown: Optional[float] = None) -> str:
    """The configuration the task experiments (control, campaign, local vs remote) run on: a copy of config/ in
    ``<scratch>/config`` (with ``slowdown``: :func:`slowdown_config`'s) with config/task_experiments.yaml's values
    set in the files it names (ConfigError naming the file and field for a file or key that is not there)."""
    from cnr_params import ConfigError
    dst = (slowdown_config(scratch, slowdown) if slowdown is not None else
           copy_config(os.path.join(scratch, 'config')))
    overlay_path = os.path.join(report.WS, 'config', TASK_OVERLAY)
    with open(overlay_path) as f:
        overlay = yaml.safe_load(f) or {}
    for name, values in overlay.items():
        path = os.path.join(dst, str(name))
        if not isinstance(values, dict) or not os.path.exists(path):
            raise ConfigError(overlay_path, str(name), 'expected a file of config/ with the values to set in it')
        set_values(path, values, overlay_path, str(name))
    return dst


def set_values(path: str, values: Dict, source: str, field: str = '') -> None:
    """Set ``values`` (nested mappings: the keys inside them) in the YAML file ``path``, rewriting it; a key the file
    does not have is a ConfigError naming ``source`` and the key's path under ``field``."""
    from cnr_params import ConfigError
    with open(path) as f:
        doc = yaml.safe_load(f) or {}

    def merge(target: Dict, new: Dict, at: str) -> None:
        for key, value in new.items():
            here = f'{at}.{key}' if at else str(key)
            if key not in target:
                raise ConfigError(source, here, f'no such key in {os.path.basename(path)}')
            if isinstance(value, dict) and isinstance(target[key], dict):
                merge(target[key], value, here)
            else:
                target[key] = value
    merge(doc, values, field)
    write_atomic(path, yaml.safe_dump(doc, sort_keys=False))


def testbed_running(prog: str) -> bool:
    """True (said in one line) when a testbed is up: its robot cgroup keeps the cap it was made with, so a
    ``--slowdown`` would not apply."""
    from cnr_testbed.api import Testbed
    if Testbed(os.path.join(report.WS, 'config', 'testbed.yaml')).running():
        print(f'{prog}: a testbed is running and its robot CPU cap would be used instead of --slowdown\'s: stop it '
              f'first (launch_scripts/testbed.sh down)', file=sys.stderr)
        return True
    return False
