#!/usr/bin/env bash
# run_mission.sh — README command (1): the data-center monitoring mission, on one master or on the testbed's
# robot and cloud (entry point cnr_mission.run; options: run_mission.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python cnr_mission.run "$@"
