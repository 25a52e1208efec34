#!/usr/bin/env bash
# bench_rtt.sh — thesis Table 4-1 / Appendix II: round trip between a client node (robot) and a monitor node
# through topics (echo) and services (naive and persistent clients) in the placements M-M, C-Ma, C-Mo and Multi
# at link RTTs 0, 20, 50, 100 ms, 20 samples each, on the testbed. Needs root. Writes bench_results/rtt.tsv,
# rtt.md (thesis beside ours) and rtt.png. About 10 minutes.
#
#   launch_scripts/bench_rtt.sh [--rtts 0,20,50,100] [--samples 20] [--interval 0.25]
#                               [--placements M-M,C-Ma,C-Mo,Multi] [--out DIR]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.rtt "$@"
