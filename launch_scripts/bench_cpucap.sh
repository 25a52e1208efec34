#!/usr/bin/env bash
# bench_cpucap.sh — measure the robot's CPU cap (config/testbed.yaml testbed.robot_cpu): the slowdown of a
# CPU-bound Python loop inside the cgroup against outside, and the wake-up lateness of a 10 ms periodic loop
# under a CPU hog in the same cgroup for CFS periods of 1-100 ms. Needs root; about a minute.
# Writes bench_results/cpucap.md and cpucap.json.
#
#   launch_scripts/bench_cpucap.sh [--out DIR] [--repeats N] [--seconds S]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (cgroups)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_testbed.cpucap_bench "$@"
