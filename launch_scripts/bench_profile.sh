#!/usr/bin/env bash
# bench_profile.sh — accuracy and cost of network_monitor's profile on the testbed: for each link RTT
# (0, 20, 50, 100, 150 ms, as two one-way halves) x rate (1, 3.4, 10, 50 Mbit/s both ways), after an unshaped
# 0 ms baseline: the profile's RTT vs set + baseline (target +/-2 ms), the probe's A_bw vs the rate (+/-10 %),
# the passive estimate 10 s after the probe under 0.5 x rate of background load (+/-20 %), and the probe's
# cost (bytes on the link, seconds per ~profile_now). Two masters joined by multimaster_bridge, a
# network_monitor on each (config/network_monitor.yaml), on its own testbed instance (default name bp:
# namespaces bp-robot/bp-cloud, so a running cnr testbed is never touched). Needs root. Writes
# bench_results/profile.tsv (every repetition) and profile.md (table). About 15 minutes (--quick: 2 RTT x 2
# rates, 1 repetition, about 2 minutes).
#
#   launch_scripts/bench_profile.sh [--quick] [--reps N (default 2)] [--name bp] [--out DIR] [--config testbed.yaml]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.profile_bench "$@"
