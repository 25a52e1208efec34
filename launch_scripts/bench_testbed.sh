#!/usr/bin/env bash
# bench_testbed.sh — the link emulator's added RTT and throughput (root), page in docs/results/testbed
# (entry point cnr_benchmarks.testbed; options: bench_testbed.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.testbed "$@"
