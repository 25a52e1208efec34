#!/usr/bin/env bash
# bench_rtt.sh — thesis Table 4-1 / Appendix II: client-monitor RTT by placement (root), page in docs/results/rtt
# (entry point cnr_benchmarks.rtt; options: bench_rtt.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.rtt "$@"
