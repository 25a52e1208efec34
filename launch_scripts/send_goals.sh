#!/usr/bin/env bash
# send_goals.sh — send navigation goals to move_base through its action interface, printing progress
# (entry point cnr_navigation.goal_sequencer; options: send_goals.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python cnr_navigation.goal_sequencer "$@"
