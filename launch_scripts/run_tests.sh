#!/usr/bin/env bash
# run_tests.sh — set up the workspace and run the test suite (unit + integration, rostest-style pytest).
#
#   launch_scripts/run_tests.sh [--fast] [--workers N] [pytest args...]     e.g.  -k mapio   or   tests/test_cnr_maps.py
#
#   --fast       only the ROS-free unit tests: no master, no nodes (pytest -m "not integration"), in one process.
#   --workers N  pytest-xdist worker processes for the whole suite (default 2; 0 = one process). The tests that
#                use the default testbed (real-time two-host missions) run one after the other in one worker
#                (xdist group "default_testbed"); every other test has its own master, testbed name and ports.
#
# Integration tests start their own rosmaster on a free port (never 11311) and stop everything they start.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
args=(); tier=(); workers=2
while [ $# -gt 0 ]; do
  case "$1" in
    --fast) tier=(-m "not integration"); workers=0; shift ;;
    --workers) [[ "${2:-}" =~ ^[0-9]+$ ]] || cnr_die "--workers: expected a number of processes, got '${2:-}'"
               workers="$2"; shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done
parallel=()
if [ "$workers" -gt 0 ]; then parallel=(-n "$workers" --dist loadgroup); fi
"$CNR_WS/launch_scripts/setup.sh"
cnr_source_ws
cd "$CNR_WS"
exec /usr/bin/python3 -m pytest tests "${tier[@]}" "${parallel[@]}" "${args[@]}"
