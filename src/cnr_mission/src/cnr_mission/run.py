"""The data-center monitoring mission (thesis §4.1, paper Appendix VI).

Which mission runs: with no host option (none of --single-master, --two-host, --migration, --rule,
--network-aware, --placement) it runs the network-aware mission (--network-aware patrol, below) when it can:
as root, with /dev/net/tun, in the corridor (the scenario of the link map config/link_map_corridor.yaml) and
in real time (no --rtf other than 1). Otherwise, and with --single-master, it runs the single-master mission
and says why in one line.

Single master: sets up the workspace, starts a master (default port 11311, or --port, or ROS_MASTER_URI),
brings up the simulated TurtleBot with the monitoring modules (kestrel_driver, merger, local_mapcell_manager,
global_goal_manager, mfg) and prints progress until the hotspot is found (plus the scenario's extra time).
Writes a report folder (default reports/<scenario>-<date>): mapcells.png, measurements.tsv, summary.json.
Ctrl-C stops everything it started.

Two hosts (root): --two-host runs the mission on the testbed (launch_scripts/testbed.sh; brought up and down
unless one is up): a master, bridge and network_monitor on the robot and on the cloud, the modules on their
hosts by --placement (config/placements.yaml: all_robot, move_base_cloud, paper_normal, paper_network_aware,
monitoring_cloud; or a YAML file {module: host}; default move_base_cloud), the robot's computer inside its
CPU cgroup (config/testbed.yaml robot_cpu). The link: --delay, --rate, --loss, or --trace FILE or --link-map
FILE (conditions by robot position, e.g. config/link_map_corridor.yaml). Two-host runs are real-time (the
emulator's delays are wall-clock time). --migration: the modules of config/migration.yaml are started by
migration agents where the placement says and can be moved while the mission runs (launch_scripts/migrate.sh;
src/migration_manager/README.md); --rule also moves them by the link quality (config/migration.yaml rule).
--network-aware [TASK]: network_monitor's migration_decider places the modules of TASK (config/decision.yaml
tasks, default patrol: mfg and global_goal_manager) by the learned k-NN decision when the mission starts,
re-decides as the link changes and evaluates the mission at its end (default placement all_robot, link map
config/link_map_corridor.yaml). The report adds the placement, link.tsv (conditions and bytes over time), the
bytes over the link and, network-aware, decisions.tsv.

Watching: --view opens rviz (config/mission.rviz with cnr_viz's markers: mapcells by temperature, the search,
the goals, the hotspot, the link map's dead zones, where each module runs) beside the mission when $DISPLAY is
set, on two hosts attached to the robot's master, and saves its last view as view.png in the report; --record
writes the mission's rosbag, mission.bag, into the report. Every report has timeline.png (each module's host,
the link's RTT and outages, measurements per second, decisions and migrations).

Exit status: 0 hotspot found, 3 not found, 2 bad configuration, 130 interrupted, 1 anything else.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import List, Optional, Tuple

from cnr_bringup.launcher import EXIT_INTERRUPTED, NOISE
from cnr_harness.script import WS, Interrupted, Parser, Processes, ScriptError, log, master_address, master_up, \
    port_number, run, setup_workspace
from cnr_mission.options import DEFAULT_TASK, EXIT_NOT_FOUND, add_link_arguments, add_migration_arguments
from cnr_params.config import EXIT_CONFIG, ConfigError

PROG = 'run_mission.sh'
DEFAULT_PLACEMENT = 'move_base_cloud'
NETWORK_AWARE_PLACEMENT = 'all_robot'
NETWORK_AWARE_SCENARIO = 'corridor'     # the scenario of the network-aware mission's link map
LINK_MAP = os.path.join(WS, 'config', 'link_map_corridor.yaml')


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    ap = Parser(PROG, __doc__)
    ap.add_argument('--scenario', default='corridor', metavar='corridor|datacenter|FILE.yaml',
                    help='config/scenarios/NAME.yaml or a scenario file (default corridor)')
    ap.add_argument('--port', type=port_number,
                    help='master port (default: ROS_MASTER_URI, else 11311; two hosts: 11311)')
    ap.add_argument('--rtf', metavar='FACTOR', help='real-time factor, single master: 1 real time, 5 five times '
                    'faster (default), 0 as fast as possible; two hosts: 1 only')
    ap.add_argument('--report-dir', type=os.path.realpath, metavar='DIR',
                    help='the report folder, empty or new (default reports/<scenario>-<date>)')
    ap.add_argument('--view', action='store_true', help="open rviz beside the mission (config/mission.rviz, cnr_viz's "
                    "markers) when $DISPLAY is set; its last view is saved as view.png in the report")
    ap.add_argument('--record', action='store_true', help='record the mission into mission.bag in the report '
                    '(rosbag; the topics of config/viz.yaml record.topics)')
    hosts = ap.add_argument_group('hosts')
    hosts.add_argument('--single-master', action='store_true', help='the single-master mission')
    hosts.add_argument('--two-host', action='store_true', help='robot and cloud on the testbed (root)')
    hosts.add_argument('--placement', metavar='NAME|FILE', help='which module runs where (implies --two-host; '
                       f'default {DEFAULT_PLACEMENT}, network-aware {NETWORK_AWARE_PLACEMENT})')
    add_migration_arguments(hosts)
    link = ap.add_argument_group('link (two hosts)')
    add_link_arguments(link, path=os.path.realpath)
    return ap.parse_args(argv)


def single_master_reason(scenario: str, rtf: Optional[str], euid: int, has_tun: bool) -> str:
    """Why the mission without a host option runs on a single master ('' when the network-aware mission can run)."""
    if euid != 0:
        return 'not root (robot and cloud need network namespaces, TUN devices and a CPU cgroup)'
    if not has_tun:
        return "no /dev/net/tun (the testbed's link emulator needs it)"
    if scenario != NETWORK_AWARE_SCENARIO:
        return (f"--scenario {scenario}: the network-aware mission's link map (config/link_map_corridor.yaml) is "
                f"the {NETWORK_AWARE_SCENARIO}'s")
    if rtf is not None and rtf != '1':
        return f'--rtf {rtf}: two hosts run in real time'
    return ''


def choose_hosts(args: argparse.Namespace) -> None:
    """Settle ``args.two_host`` and ``args.network_aware``: the options given, else the default policy (which
    says in one line which mission runs)."""
    args.two_host = bool(args.two_host or args.migration or args.rule or args.network_aware or args.placement)
    if args.two_host or args.single_master:
        return
    why = single_master_reason(args.scenario, args.rtf, os.geteuid(), os.path.exists('/dev/net/tun'))
    if why:
        log(PROG, f'single-master mission: {why}')
        return
    args.two_host, args.network_aware = True, DEFAULT_TASK
    log(PROG, 'network-aware mission (robot and cloud on the testbed; --single-master for one host)')


def scenario_file(scenario: str) -> str:
    path = (os.path.realpath(scenario) if scenario.endswith('.yaml')
            else os.path.join(WS, 'config', 'scenarios', f'{scenario}.yaml'))
    if not os.path.isfile(path):
        raise ScriptError(f'scenario not found: {path} (see config/scenarios/)')
    return path


def check_scenario(path: str) -> Tuple[str, str, List[str]]:
    """``check_scenario FILE`` (each node's own parameter rules, before anything is launched): the scenario's
    name, map (absolute path) and start x y yaw. It states a problem in one line naming file and field: exit 2."""
    out = subprocess.run(['rosrun', 'cnr_mission', 'check_scenario', path], stdout=subprocess.PIPE, text=True)
    fields = out.stdout.split()
    if out.returncode != 0 or len(fields) != 5:
        raise SystemExit(EXIT_CONFIG)
    return fields[0], fields[1], fields[2:]


def report_folder(report: Optional[str], name: str) -> str:
    """The report folder, created; one run per folder (its measurement store and relay queues would be reloaded
    by the next run)."""
    report = report or os.path.join(WS, 'reports', f'{name}-{time.strftime("%Y%m%d-%H%M%S")}')
    if os.path.exists(report) and (not os.path.isdir(report) or os.listdir(report)):
        raise ScriptError(f'report folder {report} is not empty (it holds another run; choose another --report-dir)')
    os.makedirs(report, exist_ok=True)
    return report


def link_given(args: argparse.Namespace) -> bool:
    return any(v is not None for v in (args.delay, args.rate, args.loss, args.trace, args.link_map))


def run_two_host(args: argparse.Namespace, scenario: str, name: str, map_file: str, start: List[str],
                 report: str) -> int:
    from cnr_mission.two_host import TwoHostOptions, run as run_two_host_mission
    placement = args.placement or (NETWORK_AWARE_PLACEMENT if args.network_aware else DEFAULT_PLACEMENT)
    if placement.endswith(('.yaml', '.yml')) or '/' in placement:
        placement = os.path.realpath(placement)
    link_map = args.link_map
    if args.network_aware and not link_given(args):
        link_map = LINK_MAP
    if args.rtf is not None and args.rtf != '1':
        raise ScriptError("--two-host runs in real time (the link emulator's delays and rates are wall-clock time, "
                          "the robot's CPU cap is per wall second): --rtf 1 or leave it out")
    if os.geteuid() != 0:
        raise ScriptError('--two-host needs root (network namespaces, TUN devices, cgroups)')
    log(PROG, f'scenario {name} ({scenario}) on two hosts, placement {placement}, report in {report}')
    return run_two_host_mission(TwoHostOptions(
        config_dir=os.path.join(WS, 'config'), scenario=scenario, map=map_file, start=start, placement=placement,
        report_dir=report, port=args.port or 11311, delay=args.delay, rate=args.rate, loss=args.loss,
        trace=args.trace, link_map=link_map, migration=args.migration, rule=args.rule,
        network_aware=args.network_aware, view=view_display(args.view), record=args.record))


def run_single_master(args: argparse.Namespace, scenario: str, name: str, map_file: str, start: List[str],
                      report: str) -> int:
    if link_given(args):
        raise ScriptError('--delay/--rate/--loss/--trace/--link-map need --two-host')
    _, port = master_address(None, args.port)
    if master_up():
        raise ScriptError(f'a master already runs at {os.environ["ROS_MASTER_URI"]}; stop it or choose --port')
    rtf = args.rtf if args.rtf is not None else '5'
    try:
        return _launch_mission(port, scenario, name, map_file, start, rtf, report, args.view, args.record)
    except Interrupted:
        return EXIT_INTERRUPTED


def _launch_mission(port: int, scenario: str, name: str, map_file: str, start: List[str], rtf: str,
                    report: str, view: bool = False, record: bool = False) -> int:
    x, y, a = start
    with Processes() as procs:
        procs.ensure_master(PROG, port)
        log(PROG, f'scenario {name} ({scenario}), real-time factor {rtf}, report in {report}')
        viewer = start_viewer(procs, scenario, report, view, record)
        # cnr_launch: roslaunch that ends at once with exit 2 when a node reports a configuration error, and ends
        # quietly when the mission monitor is done (its exit status: 0 hotspot found, 3 not found)
        launch = procs.start(['rosrun', 'cnr_bringup', 'cnr_launch', '--until', 'mission_monitor', 'cnr_mission',
                              'mission.launch', 'monitor_required:=false', f'scenario_file:={scenario}',
                              f'map:={map_file}', f'x:={x}', f'y:={y}', f'a:={a}', f'real_time_factor:={rtf}',
                              f'report_dir:={report}', f'store:={report}/store.tsv',
                              f'viz:={str(view or record).lower()}'],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors='replace')
        for line in launch.stdout:
            if not NOISE.match(line):
                print(line, end='', flush=True)
        status = launch.wait()
        if viewer:
            save_view(viewer, report)
        return status


def start_viewer(procs: Processes, scenario: str, report: str, view: bool, record: bool) -> Optional[Tuple]:
    """``--record``: rosbag records the mission into the report; ``--view``: rviz opens beside it when there is a
    display (else one line why not). The rviz process and its window title, to save its view at the end."""
    from cnr_viz import viewer
    config_dir = os.path.join(WS, 'config')
    logs = os.path.join(report, 'logs')
    if record:
        os.makedirs(logs, exist_ok=True)
        with open(os.path.join(logs, 'rosbag_record.log'), 'w') as out:
            procs.start(viewer.record_argv(config_dir, report), stdout=out, stderr=subprocess.STDOUT)
        log(PROG, f'recording the mission into {os.path.join(report, viewer.BAG)}')
    display = view_display(view)
    if not display:
        return None
    os.makedirs(logs, exist_ok=True)
    rviz_cfg, _, view_cfg = viewer.write_rviz_config(config_dir, scenario, logs)

    def start() -> subprocess.Popen:
        with open(os.path.join(logs, 'rviz.log'), 'a') as out:
            return procs.start(viewer.rviz_argv(rviz_cfg), stdout=out, stderr=subprocess.STDOUT)
    rviz = viewer.open_rviz(start, display, view_cfg)       # its window up before the mission starts
    if rviz is None:
        log(PROG, f'--view: rviz ended {view_cfg.rviz_attempts} times before its window showed (logs/rviz.log)')
        return None
    return rviz, display, view_cfg


def check_viewer() -> None:
    """config/viz.yaml before anything starts (--view, --record): a problem is one line naming file and field."""
    from cnr_viz.viewer import check_config
    try:
        check_config(os.path.join(WS, 'config'))
    except ConfigError as exc:
        raise ScriptError(str(exc)) from None


def view_display(view: bool) -> str:
    """The display rviz opens on with ``--view`` ('' with one line why not, or without ``--view``)."""
    if not view:
        return ''
    from cnr_viz.viewer import display_problem
    display = os.environ.get('DISPLAY', '')
    why = display_problem(display)
    if why:
        log(PROG, f'--view: rviz not opened: {why}; the markers are on /viz_markers/markers')
        return ''
    log(PROG, f'--view: rviz on {display}')
    return display


def save_view(viewer_state: Tuple, report: str) -> None:
    """rviz's last view (it keeps the markers after the mission's nodes stopped) as view.png in the report."""
    from cnr_viz.viewer import screenshot
    rviz, display, view_cfg = viewer_state
    if rviz.poll() is not None:
        log(PROG, f'--view: rviz ended (status {rviz.returncode}) before the mission; no view.png')
        return
    try:
        log(PROG, f'--view: the last view saved as {screenshot(display, view_cfg, report)}')
    except Exception as exc:      # Xlib raises its own classes; the report stands without the picture
        log(PROG, f'--view: no view.png ({exc})')


def outcome(status: int, report: str) -> int:
    """The script's exit status from the mission's: the report's ``found`` decides between 0 and 3."""
    if status == EXIT_CONFIG:
        log(PROG, 'stopped: a node reported a configuration error (above)')
        return EXIT_CONFIG
    if status == EXIT_INTERRUPTED:
        log(PROG, 'interrupted')
        return EXIT_INTERRUPTED
    try:
        with open(os.path.join(report, 'summary.json')) as f:
            found = json.load(f).get('found')
    except (OSError, ValueError):
        found = None
    if found is True:
        log(PROG, f'hotspot found; report: {report}')
        return 0
    if found is False:
        log(PROG, f'no hotspot found; report: {report}')
        return EXIT_NOT_FOUND
    log(PROG, f'the mission ended without a report (launch exit status {status}; see ~/.ros/log/latest)')
    return 1


def mission(argv: Optional[List[str]]) -> int:
    args = parse_args(argv)
    choose_hosts(args)
    scenario = scenario_file(args.scenario)
    setup_workspace()
    name, map_file, start = check_scenario(scenario)
    if args.view or args.record:
        check_viewer()
    report = report_folder(args.report_dir, name)
    runner = run_two_host if args.two_host else run_single_master
    return outcome(runner(args, scenario, name, map_file, start, report), report)


def main(argv: Optional[List[str]] = None) -> int:
    return run(lambda: mission(argv), PROG)


if __name__ == '__main__':
    sys.exit(main())
