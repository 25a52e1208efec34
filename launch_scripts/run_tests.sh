#!/usr/bin/env bash
# run_tests.sh — set up the workspace and run the test suite (unit + integration, rostest-style pytest).
#
#   launch_scripts/run_tests.sh [pytest args...]     e.g.  -k unit   or   tests/test_mapio.py
#
# Integration tests start their own rosmaster on a free port (never 11311) and stop everything they start.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
WS="$CNR_WS"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
"$WS/launch_scripts/setup.sh"
set +u; source "$WS/devel/setup.bash"; set -u
cd "$WS"
exec /usr/bin/python3 -m pytest tests "$@"
