#!/usr/bin/env bash
# run_tests.sh — set up the workspace and run the test suite (unit + integration, rostest-style pytest).
#
#   launch_scripts/run_tests.sh [--fast] [pytest args...]     e.g.  -k unit   or   tests/test_mapio.py
#
#   --fast  only the ROS-free unit tests: no master, no nodes (pytest -m "not integration").
#
# Integration tests start their own rosmaster on a free port (never 11311) and stop everything they start.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
args=(); tier=()
for arg in "$@"; do
  if [ "$arg" = --fast ]; then tier=(-m "not integration"); else args+=("$arg"); fi
done
"$CNR_WS/launch_scripts/setup.sh"
cnr_source_ws
cd "$CNR_WS"
exec /usr/bin/python3 -m pytest tests "${tier[@]}" "${args[@]}"
