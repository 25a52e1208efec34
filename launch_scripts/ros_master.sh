#!/usr/bin/env bash
# ros_master.sh — start a ROS master (roscore: rosmaster + rosout) on a chosen address, like `roscore -p`.
#
#   launch_scripts/ros_master.sh [--host HOST] [--port PORT]
#
# Address: arguments, else ROS_MASTER_URI, else http://localhost:11311. Runs in the foreground;
# Ctrl-C stops it. Prints the ROS_MASTER_URI to export in other shells.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
host=""; port=""
while [ $# -gt 0 ]; do
  case "$1" in
    --host) host="${2:?--host needs a value}"; shift 2 ;;
    --port) port="${2:?--port needs a value}"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
cnr_source_ws
cnr_master_uri "$host" "$port"
cnr_master_up && cnr_die "a master already answers at $ROS_MASTER_URI"
cnr_ensure_master
cnr_log "master up: export ROS_MASTER_URI=$ROS_MASTER_URI   (Ctrl-C to stop)"
wait "${CNR_PIDS[0]}"
