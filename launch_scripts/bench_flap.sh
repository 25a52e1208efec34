#!/usr/bin/env bash
# bench_flap.sh — the split mission under a flapping link (root), page in docs/results/flap
# (entry point cnr_benchmarks.flap; options: bench_flap.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.flap "$@"
