#!/usr/bin/env bash
# bringup.sh — bring up the simulated TurtleBot 2 (simulator, map_server, move_base) on a master.
#
#   launch_scripts/bringup.sh [--map corridor|datacenter|FILE.yaml] [--host H] [--port P]
#                             [--rtf FACTOR] [--pose X Y YAW] [--obstacles] [--no-nav]
#                             [--controller-frequency HZ] [-- extra roslaunch args]
#   --controller-frequency: move_base's control rate (default: config/navigation/move_base.yaml).
#
# Starts a master first if none answers at the address (arguments, else ROS_MASTER_URI, else
# localhost:11311). Runs in the foreground; Ctrl-C stops everything it started.
#   --rtf 1.0 real time (default), 5 = five times faster, 0 = as fast as possible.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
host=""; port=""; map="corridor"; rtf="1.0"; nav="true"; obstacles="false"; rate=""
x="0.5"; y="0.0"; yaw="0.0"; pose_given=0; extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --host) host="${2:?}"; shift 2 ;;
    --port) port="${2:?}"; shift 2 ;;
    --map) map="${2:?}"; shift 2 ;;
    --rtf) rtf="${2:?}"; shift 2 ;;
    --pose) x="${2:?}"; y="${3:?}"; yaw="${4:?}"; pose_given=1; shift 4 ;;
    --obstacles) obstacles="true"; shift ;;
    --no-nav) nav="false"; shift ;;
    --controller-frequency) rate="${2:?}"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
case "$map" in
  corridor|datacenter) map_file="$CNR_WS/maps/$map.yaml" ;;
  *) map_file="$(realpath -m "$map")" ;;
esac
[ -f "$map_file" ] || cnr_die "map file not found: $map_file"
if [ "$pose_given" = 0 ] && [ "$map" = datacenter ]; then x="1.0"; y="1.0"; yaw="0.0"; fi
for v in "$rtf" "$x" "$y" "$yaw" ${rate:+"$rate"}; do
  [[ "$v" =~ ^-?[0-9]+(\.[0-9]+)?$ ]] || cnr_die "not a number: '$v'"
done
cnr_source_ws
cnr_master_uri "$host" "$port"
cnr_ensure_master
cnr_log "bringing up the TurtleBot on $ROS_MASTER_URI (map $map_file, real-time factor $rtf)"
# cnr_launch: roslaunch that stops at once with exit 2 when a node reports a configuration error
cnr_spawn rosrun cnr_bringup cnr_launch cnr_bringup robot.launch map:="$map_file" real_time_factor:="$rtf" \
  x:="$x" y:="$y" a:="$yaw" obstacles:="$obstacles" navigation:="$nav" \
  ${rate:+controller_frequency:="$rate"} "${extra[@]}"
wait "${CNR_PIDS[-1]}"
