#!/usr/bin/env bash
# migrate.sh — ask the migration manager to move a module between the robot and the cloud, or show where
# each module runs (src/migration_manager/README.md).
#
#   launch_scripts/migrate.sh [--host H] [--port P] MODULE robot|cloud [--mode cold|hot]
#   launch_scripts/migrate.sh [--host H] [--port P] --placement
#
# MODULE: move_base, local_mapcell_manager, global_goal_manager or mfg (config/migration.yaml modules).
# The manager runs on the robot's master: on the testbed, run this inside the robot's namespace
# (ip netns exec robot launch_scripts/migrate.sh ... --host 10.77.0.1). Exit status: 0 done, 1 rolled back
# or failed, 2 refused, 3 no migration manager answering.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
host=""; port=""; rest=()
while [ $# -gt 0 ]; do
  case "$1" in
    --host) host="${2:?}"; shift 2 ;;
    --port) port="${2:?}"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) rest+=("$1"); shift ;;
  esac
done
cnr_source_ws
cnr_master_uri "$host" "$port"
cnr_master_up || { echo "$(basename "$0"): no master at $ROS_MASTER_URI" >&2; exit 3; }
exec rosrun migration_manager migrate "${rest[@]}"
