#!/usr/bin/env bash
# bench_startup.sh — thesis Table 4-2 / Appendix III: move_base start-up, single vs multi-master (root), page in
# docs/results/startup (entry point cnr_benchmarks.startup; options: bench_startup.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.startup "$@"
