#!/usr/bin/env bash
# bringup.sh — bring up the simulated TurtleBot 2 (simulator, map_server, move_base) on a master
# (entry point cnr_bringup.bringup; options: bringup.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python cnr_bringup.bringup "$@"
