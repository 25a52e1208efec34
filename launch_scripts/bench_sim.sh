#!/usr/bin/env bash
# bench_sim.sh — the simulator and navigation benchmarks (thesis §3), page in docs/results/sim
# (entry point cnr_benchmarks.sim_suite; options: bench_sim.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.sim_suite "$@"
