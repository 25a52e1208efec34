#!/usr/bin/env bash
# send_goals.sh — send navigation goals to move_base through its action interface, printing progress.
#
#   launch_scripts/send_goals.sh [--host H] [--port P] [--goals FILE.yaml | X Y YAW]
#
# FILE holds `goals: [{name: .., x: .., y: .., yaw: ..}, ...]` (all required) in the map frame (default config/goals_corridor.yaml).
# Exits 0 when every goal succeeded, 1 otherwise.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
host=""; port=""; goals="$CNR_WS/config/goals_corridor.yaml"; single=()
while [ $# -gt 0 ]; do
  case "$1" in
    --host) host="${2:?}"; shift 2 ;;
    --port) port="${2:?}"; shift 2 ;;
    --goals) goals="$(realpath -m "${2:?}")"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) [ $# -ge 3 ] || cnr_die "expected X Y YAW or --goals FILE (see --help)"; single=("$1" "$2" "$3"); shift 3 ;;
  esac
done
cnr_source_ws
cnr_master_uri "$host" "$port"
cnr_master_up || cnr_die "no master at $ROS_MASTER_URI (start one with launch_scripts/bringup.sh)"
if [ ${#single[@]} -eq 3 ]; then
  cnr_spawn rosrun cnr_navigation goal_sequencer --goal "${single[@]}"
else
  cnr_spawn rosrun cnr_navigation goal_sequencer --goals "$goals"
fi
set +e; wait "${CNR_PIDS[-1]}"; rc=$?; set -e
exit $rc
