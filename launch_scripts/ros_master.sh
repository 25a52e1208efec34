#!/usr/bin/env bash
# ros_master.sh — start a ROS master (roscore: rosmaster + rosout) on a chosen address, like `roscore -p`
# (entry point cnr_bringup.ros_master; options: ros_master.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python cnr_bringup.ros_master "$@"
