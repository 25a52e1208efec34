#!/usr/bin/env bash
# bench_profile.sh — network_monitor's profile accuracy and probe cost (root), page in docs/results/profile
# (--probe-method train: docs/results/profile_train; entry point cnr_benchmarks.profile_bench; options:
# bench_profile.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.profile_bench "$@"
