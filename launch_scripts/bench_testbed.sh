#!/usr/bin/env bash
# bench_testbed.sh — measure the link emulator: added RTT for 0..200 ms settings, throughput at 1, 10, 50
# Mbit/s and unshaped (ping, iperf3). Needs root. Writes bench_results/testbed.tsv and testbed.md.
#
#   launch_scripts/bench_testbed.sh [--out DIR]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_testbed.bench "$@"
