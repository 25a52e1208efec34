#!/usr/bin/env bash
# run_demo.sh — README command (1): the navigation demo in the thesis's lab corridor.
#
#   launch_scripts/run_demo.sh [--map corridor|datacenter] [--port P] [--rtf FACTOR] [--goals FILE]
#
# Sets up the workspace (launch_scripts/setup.sh), starts a master (default port 11311, or --port,
# or ROS_MASTER_URI), brings up the simulated TurtleBot 2 with navigation, drives it through the
# goal sequence printing progress, then stops everything it started.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
port=""; map="corridor"; rtf="1.0"; goals=""
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port="${2:?}"; shift 2 ;;
    --map) map="${2:?}"; shift 2 ;;
    --rtf) rtf="${2:?}"; shift 2 ;;
    --goals) goals="$(realpath -m "${2:?}")"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
[ -n "$goals" ] || goals="$CNR_WS/config/goals_${map}.yaml"
[ -f "$goals" ] || cnr_die "goal file not found: $goals"
"$CNR_WS/launch_scripts/setup.sh"
cnr_source_ws
cnr_master_uri "" "$port"
cnr_master_up && cnr_die "a master already runs at $ROS_MASTER_URI; stop it or choose --port"
cnr_ensure_master
cnr_spawn "$CNR_WS/launch_scripts/bringup.sh" --map "$map" --rtf "$rtf"
set +e
rosrun cnr_navigation goal_sequencer --goals "$goals" --server-timeout 180
rc=$?
set -e
[ $rc = 0 ] && cnr_log "demo finished: every goal reached" || cnr_log "demo finished: some goals failed (exit $rc)"
exit $rc
