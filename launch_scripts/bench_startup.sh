#!/usr/bin/env bash
# bench_startup.sh — thesis Table 4-2 / Appendix III: start-up time of the navigation node (move_base) on the
# cloud host, from process start until its action server is usable from the robot's master, with a single master
# (the robot's) versus one master per host joined by multimaster_bridge, at link RTTs 0, 20, 50, 100, 120, 140 ms,
# 5 runs each. Needs root. Writes bench_results/startup.tsv, startup.md (thesis beside ours) and startup.png.
# The single-master runs dominate: about 30 minutes in all.
#
#   launch_scripts/bench_startup.sh [--rtts 0,20,50,100,120,140] [--runs 5] [--modes SM,MM] [--out DIR]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.startup "$@"
