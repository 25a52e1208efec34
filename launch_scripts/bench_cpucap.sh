#!/usr/bin/env bash
# bench_cpucap.sh — the robot's CPU cap: slowdown and wake-up lateness (root), page in docs/results/cpucap
# (entry point cnr_benchmarks.cpucap; options: bench_cpucap.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.cpucap "$@"
