#!/usr/bin/env bash
# run_mission.sh — README command (1): the data-center monitoring mission (thesis §4.1, paper Appendix VI).
#
#   launch_scripts/run_mission.sh [--scenario corridor|datacenter|FILE.yaml] [--port P] [--rtf FACTOR]
#                                 [--report-dir DIR] [--single-master]
#   launch_scripts/run_mission.sh --two-host [--placement NAME|FILE] [--scenario ...] [--port P] [--report-dir DIR]
#                                 [--delay MS] [--rate MBIT] [--loss PCT] [--trace FILE] [--link-map FILE]
#                                 [--migration [--rule] | --network-aware [TASK]]
#
# With no host option (none of --two-host, --migration, --rule, --network-aware, --placement, --single-master)
# it runs the network-aware mission (below: --network-aware patrol) when it can: as root, with /dev/net/tun,
# in the corridor (the scenario of the link map config/link_map_corridor.yaml) and in real time (no --rtf
# other than 1). Otherwise, and with --single-master, it runs the single-master mission and says why in one
# line.
#
# Single master: sets up the workspace, starts a master (default port 11311, or --port, or ROS_MASTER_URI), brings up the
# simulated TurtleBot with the monitoring modules (kestrel_driver, merger, local_mapcell_manager,
# global_goal_manager, mfg) and prints progress until the hotspot is found (plus the scenario's extra
# time). Writes a report folder (default reports/<scenario>-<date>): mapcells.png, measurements.tsv,
# summary.json. Exit status 0 when the hotspot was found. Ctrl-C stops everything it started.
#   --rtf 1 real time (default 5: five times faster than real time), 0 = as fast as possible.
#
# Two hosts (root): --two-host runs the mission on the testbed (launch_scripts/testbed.sh; brought up and
# down unless one is up): a master, bridge and network_monitor on the robot and on the cloud, the modules on
# their hosts by --placement (config/placements.yaml: all_robot, move_base_cloud, paper_normal,
# paper_network_aware, monitoring_cloud; or a YAML file {module: host}; default move_base_cloud), the robot's
# computer inside its CPU cgroup (config/testbed.yaml robot_cpu). The link: --delay (one-way, ms, each
# direction), --rate (Mbit/s), --loss (%), or --trace FILE (testbed.sh trace) or --link-map FILE (conditions
# by robot position, testbed.sh follow, e.g. config/link_map_corridor.yaml). Two-host runs are real-time
# (the emulator's delays are wall-clock time). --migration: the modules of config/migration.yaml are started
# by migration agents where the placement says and can be moved while the mission runs
# (launch_scripts/migrate.sh; src/migration_manager/README.md); --rule also moves them by the link quality
# (config/migration.yaml rule). --network-aware [TASK]: network_monitor's migration_decider places the
# modules of TASK (config/decision.yaml tasks, default patrol: mfg and global_goal_manager) by the learned
# k-NN decision when the mission starts, re-decides as the link changes and evaluates the mission at its end
# (default placement all_robot, link map config/link_map_corridor.yaml). The report adds the placement,
# link.tsv (conditions and bytes over time), the bytes over the link and, network-aware, decisions.tsv.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
port=""; scenario="corridor"; rtf="5"; report=""; two_host=""; placement="move_base_cloud"; link_args=(); rtf_given=""; migration=(); network_aware=""; placement_given=""; hosts_given=""
while [ $# -gt 0 ]; do
  case "$1" in
    --single-master) hosts_given=1; shift ;;
    --two-host) two_host=1; hosts_given=1; shift ;;
    --migration) migration+=(--migration); two_host=1; hosts_given=1; shift ;;
    --rule) migration+=(--rule); two_host=1; hosts_given=1; shift ;;
    --network-aware)
      task=patrol
      if [ $# -gt 1 ] && [ "${2#-}" = "$2" ]; then task="$2"; shift; fi
      migration+=(--network-aware "$task"); two_host=1; network_aware=1; hosts_given=1; shift ;;
    --placement) placement="${2:?}"; placement_given=1; two_host=1; hosts_given=1; shift 2 ;;
    --delay|--rate|--loss) link_args+=("$1" "${2:?}"); shift 2 ;;
    --trace|--link-map) link_args+=("$1" "$(realpath -m "${2:?}")"); shift 2 ;;
    --scenario) scenario="${2:?}"; shift 2 ;;
    --port) port="${2:?}"; shift 2 ;;
    --rtf) rtf="${2:?}"; rtf_given=1; shift 2 ;;
    --report-dir) report="$(realpath -m "${2:?}")"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
if [ -z "$hosts_given" ]; then
  why=""
  if [ "$(id -u)" != 0 ]; then why="not root (robot and cloud need network namespaces, TUN devices and a CPU cgroup)"
  elif [ ! -c /dev/net/tun ]; then why="no /dev/net/tun (the testbed's link emulator needs it)"
  elif [ "$scenario" != corridor ]; then why="--scenario $scenario: the network-aware mission's link map (config/link_map_corridor.yaml) is the corridor's"
  elif [ -n "$rtf_given" ] && [ "$rtf" != 1 ]; then why="--rtf $rtf: two hosts run in real time"
  fi
  if [ -z "$why" ]; then
    migration+=(--network-aware patrol); two_host=1; network_aware=1
    cnr_log "network-aware mission (robot and cloud on the testbed; --single-master for one host)"
  else
    cnr_log "single-master mission: $why"
  fi
fi
case "$scenario" in
  *.yaml) scenario_file="$(realpath -m "$scenario")" ;;
  *) scenario_file="$CNR_WS/config/scenarios/$scenario.yaml" ;;
esac
[ -f "$scenario_file" ] || cnr_die "scenario not found: $scenario_file (see config/scenarios/)"
"$CNR_WS/launch_scripts/setup.sh"
cnr_source_ws
# the whole scenario is checked before anything is launched (each node's own parameter rules): one line
# naming file and field and exit 2 on a problem; on success: name, map (absolute path), start x y yaw
read -r name map x y a < <(rosrun cnr_mission check_scenario "$scenario_file") || exit 2
[ -n "$report" ] || report="$CNR_WS/reports/$name-$(date +%Y%m%d-%H%M%S)"
# a report folder holds one run: its measurement store and relay queues would be reloaded by the next one
[ -z "$(ls -A "$report" 2>/dev/null)" ] || cnr_die "report folder $report is not empty (it holds another run; choose another --report-dir)"
mkdir -p "$report"
if [ -n "$network_aware" ]; then
  [ -n "$placement_given" ] || placement=all_robot
  [ "${#link_args[@]}" -gt 0 ] || link_args=(--link-map "$CNR_WS/config/link_map_corridor.yaml")
fi
if [ -n "$two_host" ]; then
  case "$placement" in *.yaml|*.yml|*/*) placement="$(realpath -m "$placement")" ;; esac
  [ -z "$rtf_given" ] || [ "$rtf" = 1 ] || cnr_die "--two-host runs in real time (the link emulator's delays and rates are wall-clock time, the robot's CPU cap is per wall second): --rtf 1 or leave it out"
  [ "$(id -u)" = 0 ] || cnr_die "--two-host needs root (network namespaces, TUN devices, cgroups)"
  cnr_log "scenario $name ($scenario_file) on two hosts, placement $placement, report in $report"
  set +e
  rosrun cnr_mission two_host_mission --config-dir "$CNR_WS/config" --scenario "$scenario_file" --map "$map" \
    --start "$x" "$y" "$a" --placement "$placement" --report-dir "$report" --port "${port:-11311}" "${link_args[@]}" "${migration[@]}"
  status=$?
  set -e
else
[ "${#link_args[@]}" = 0 ] || cnr_die "--delay/--rate/--loss/--trace/--link-map need --two-host"
cnr_master_uri "" "$port"
cnr_master_up && cnr_die "a master already runs at $ROS_MASTER_URI; stop it or choose --port"
cnr_ensure_master
cnr_log "scenario $name ($scenario_file), real-time factor $rtf, report in $report"
set +e
# cnr_launch: roslaunch that ends at once with exit 2 when a node reports a configuration error, and ends
# quietly when the mission monitor is done (its exit status: 0 hotspot found, 3 not found)
rosrun cnr_bringup cnr_launch --until mission_monitor cnr_mission mission.launch monitor_required:=false \
  scenario_file:="$scenario_file" map:="$map" x:="$x" y:="$y" a:="$a" \
  real_time_factor:="$rtf" report_dir:="$report" store:="$report/store.tsv" 2>&1 \
  | grep --line-buffered -v -e '^ \* /' -e '^\s*$' -e 'rosdep view is empty'
status=${PIPESTATUS[0]}
set -e
fi
[ "$status" = 2 ] && { cnr_log "stopped: a node reported a configuration error (above)"; exit 2; }
[ "$status" = 130 ] && { cnr_log "interrupted"; exit 130; }
found=$(/usr/bin/python3 -c "import json,sys; print(json.load(open(sys.argv[1])).get('found'))" "$report/summary.json" 2>/dev/null || echo missing)
case "$found" in
  True) cnr_log "hotspot found; report: $report"; exit 0 ;;
  False) cnr_log "no hotspot found; report: $report"; exit 3 ;;
  *) cnr_log "the mission ended without a report (launch exit status $status; see ~/.ros/log/latest)"; exit 1 ;;
esac
