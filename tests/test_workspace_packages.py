"""The catkin packages as a whole: every dependency declared, lint-clean, the brain independent of the body.

No master needed: these read package.xml, the Python sources and the launch files, and run catkin_lint.
"""
from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from typing import Dict, Set

import pytest

WS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = os.path.join(WS, 'src')

# ROS packages whose Python module has the package's name (the message packages are matched by suffix)
ROS_PYTHON_PACKAGES = {'rospy', 'actionlib', 'tf2_ros', 'dynamic_reconfigure', 'message_filters', 'roslaunch',
                       'rosgraph', 'rostest', 'rosnode', 'rostopic', 'rosservice', 'rosparam', 'rosbag'}
# the monitoring robot's brain: it must run on any body, so it never imports the simulator
BRAIN = {'kestrel_driver', 'merger', 'local_mapcell_manager', 'global_goal_manager', 'mfg', 'cnr_mission'}


def _packages() -> Dict[str, str]:
    out = {}
    for name in sorted(os.listdir(SRC)):
        if os.path.isfile(os.path.join(SRC, name, 'package.xml')):
            out[name] = os.path.join(SRC, name)
    return out


PACKAGES = _packages()


def _declared(pkg_dir: str) -> Set[str]:
    root = ET.parse(os.path.join(pkg_dir, 'package.xml')).getroot()
    tags = ('depend', 'exec_depend', 'build_export_depend', 'build_depend', 'test_depend')
    return {e.text.strip() for t in tags for e in root.findall(t) if e.text}


def _python_imports(pkg_dir: str) -> Dict[str, str]:
    """Top-level module -> first file importing it, over the package's src/, nodes/, scripts/."""
    found: Dict[str, str] = {}
    for sub in ('src', 'nodes', 'scripts'):
        for dirpath, _dirs, files in os.walk(os.path.join(pkg_dir, sub)):
            for f in files:
                path = os.path.join(dirpath, f)
                if not (f.endswith('.py') or (sub in ('nodes', 'scripts') and '.' not in f)):
                    continue
                with open(path, encoding='utf-8') as stream:
                    tree = ast.parse(stream.read(), path)
                for node in ast.walk(tree):
                    names = []
                    if isinstance(node, ast.Import):
                        names = [a.name for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                        names = [node.module]
                    for n in names:
                        found.setdefault(n.split('.')[0], os.path.relpath(path, WS))
    return found


def _launch_references(pkg_dir: str) -> Dict[str, str]:
    found: Dict[str, str] = {}
    launch_dir = os.path.join(pkg_dir, 'launch')
    if not os.path.isdir(launch_dir):
        return found
    for f in os.listdir(launch_dir):
        path = os.path.join(launch_dir, f)
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
        for name in re.findall(r'\$\(find ([A-Za-z0-9_]+)\)', text) + re.findall(r'pkg="([A-Za-z0-9_]+)"', text):
            found.setdefault(name, os.path.relpath(path, WS))
    return found


def _is_ros_dependency(module: str) -> bool:
    return module in PACKAGES or module in ROS_PYTHON_PACKAGES or module.endswith(('_msgs', '_srvs'))


@pytest.mark.parametrize('pkg', sorted(PACKAGES))
def test_every_dependency_is_declared(pkg: str) -> None:
    pkg_dir = PACKAGES[pkg]
    declared = _declared(pkg_dir)
    used = {m: where for m, where in _python_imports(pkg_dir).items() if _is_ros_dependency(m)}
    used.update(_launch_references(pkg_dir))
    missing = {m: where for m, where in used.items() if m != pkg and m not in declared}
    assert not missing, f'{pkg}/package.xml lacks dependencies used here: {missing}'


@pytest.mark.parametrize('pkg', sorted(BRAIN & set(PACKAGES)))
def test_the_brain_never_imports_the_simulator(pkg: str) -> None:
    imports = _python_imports(PACKAGES[pkg])
    assert 'cnr_sim' not in imports, f'{imports["cnr_sim"]} imports cnr_sim'
    assert 'cnr_sim' not in _declared(PACKAGES[pkg])


def test_catkin_lint_reports_no_errors_or_warnings() -> None:
    """catkin_lint -W1 (errors and warnings); a check switched off in a CMakeLists says why in a comment."""
    exe = shutil.which('catkin_lint')
    assert exe, 'catkin_lint is missing (Debian package catkin-lint; launch_scripts/setup.sh installs it)'
    r = subprocess.run([exe, '-W1', '--strict', SRC], capture_output=True, text=True, timeout=120)
    problems = [line for line in (r.stdout + r.stderr).splitlines() if ': error:' in line or ': warning:' in line]
    assert r.returncode == 0 and not problems, '\n'.join(problems) or r.stderr


def _callbacks_that_publish(path: str):
    """(class.method, decorators) for each method of a class in ``path`` that rospy calls back (a Subscriber's or
    message_filters' callback, a Service handler) and that publishes, directly or through the class's own
    methods."""
    with open(path, encoding='utf-8') as stream:
        tree = ast.parse(stream.read(), path)
    for cls in (n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)):
        methods = {f.name: f for f in cls.body if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))}

        def self_calls(fn):
            return {c.func.attr for c in ast.walk(fn) if isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute)
                    and isinstance(c.func.value, ast.Name) and c.func.value.id == 'self' and c.func.attr in methods}

        publishes = {name for name, fn in methods.items()
                     if any(isinstance(c, ast.Call) and isinstance(c.func, ast.Attribute) and c.func.attr == 'publish'
                            for c in ast.walk(fn))}
        grown = True
        while grown:
            more = {name for name, fn in methods.items() if self_calls(fn) & publishes} - publishes
            publishes |= more
            grown = bool(more)
        registered = set()
        for call in (c for c in ast.walk(cls) if isinstance(c, ast.Call)):
            name = call.func.attr if isinstance(call.func, ast.Attribute) else getattr(call.func, 'id', '')
            if name in ('Subscriber', 'Service', 'registerCallback'):
                for arg in call.args:
                    if isinstance(arg, ast.Attribute) and isinstance(arg.value, ast.Name) and arg.value.id == 'self':
                        registered.add(arg.attr)
        for name in sorted(registered & publishes):
            yield f'{cls.name}.{name}', [ast.unparse(d) for d in methods[name].decorator_list]


def test_every_callback_that_publishes_is_quiet_at_shutdown():
    """A subscriber callback or service handler that publishes can meet a topic the shutdown just closed
    (``publish() to a closed topic``); rospy would log that with a traceback at every mission's end (seen in CI
    with the merger). Each such callback is wrapped in ``cnr_runtime.quiet_at_shutdown``."""
    bare = []
    for pkg_dir in PACKAGES.values():
        for dirpath, _dirs, files in os.walk(os.path.join(pkg_dir, 'src')):
            for f in (f for f in files if f.endswith('.py')):
                path = os.path.join(dirpath, f)
                for method, decorators in _callbacks_that_publish(path):
                    if 'quiet_at_shutdown' not in decorators:
                        bare.append(f'{os.path.relpath(path, WS)}: {method}')
    assert not bare, bare


def test_the_launches_set_the_parameter_rospy_reads_on_every_log_call():
    """rospy reads /rosout_disable_topics_generation on every log call and asks the master each time while it
    is unset (one XML-RPC round trip per loginfo). The launches that start each master's graph set it: robot.launch
    (every single-master mission and the two-host robot, through mission.launch and world.launch) and host.launch
    (each host of the two-host mission)."""
    for rel in ('cnr_bringup/launch/robot.launch', 'cnr_mission/launch/host.launch'):
        root = ET.parse(os.path.join(SRC, rel)).getroot()
        params = {p.get('name'): p.get('value') for p in root.findall('param')}
        assert params.get('/rosout_disable_topics_generation') == 'false', f'{rel} does not set it'


HISTORY_WORD = re.compile(r'session [0-9]', re.IGNORECASE)
HISTORY_STAMP = re.compile(r'_s[0-9]+[a-z]?(?=[._])')        # e.g. migration_s25_hot.md, results_s3.tsv


def test_the_tracked_files_speak_of_the_product_not_of_its_history():
    """No tracked text file says "session N", and no tracked file name carries a history stamp such as ``_s25``:
    the product describes itself as it is (git keeps the history). Reads ``git ls-files``; no master."""
    names = subprocess.run(['git', 'ls-files', '-z'], cwd=WS, capture_output=True, check=True).stdout
    words, stamps = [], []
    for name in filter(None, names.decode().split('\0')):
        if HISTORY_STAMP.search(os.path.basename(name)):
            stamps.append(name)
        path = os.path.join(WS, name)
        if not os.path.isfile(path):        # deleted in the working tree
            continue
        with open(path, 'rb') as f:
            data = f.read()
        if b'\0' in data[:8192]:            # binary (images)
            continue
        for number, line in enumerate(data.decode('utf-8', 'replace').splitlines(), 1):
            if HISTORY_WORD.search(line):
                words.append(f'{name}:{number}: {line.strip()[:100]}')
    assert not words, 'history words in tracked files:\n' + '\n'.join(words)
    assert not stamps, 'history stamps in tracked file names:\n' + '\n'.join(stamps)


def test_the_package_dependency_graph_has_no_cycle() -> None:
    """The workspace's packages depend on each other without a cycle (ros_best_practices: an acyclic package graph)."""
    graph = {pkg: _declared(path) & set(PACKAGES) for pkg, path in PACKAGES.items()}
    state: Dict[str, int] = {}               # 1 on the current path, 2 done

    def visit(pkg: str, path: list) -> None:
        state[pkg] = 1
        for dep in sorted(graph[pkg]):
            assert state.get(dep) != 1, 'package dependency cycle: ' + ' -> '.join(path + [pkg, dep])
            if dep not in state:
                visit(dep, path + [pkg])
        state[pkg] = 2

    for pkg in sorted(graph):
        if pkg not in state:
            visit(pkg, [])
