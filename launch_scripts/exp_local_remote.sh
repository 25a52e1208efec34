#!/usr/bin/env bash
# exp_local_remote.sh — thesis Figs. 5-5 and 5-6, local vs remote move_base (root), page in docs/results/local_remote
# (entry point cnr_benchmarks.campaign local_remote; options: exp_local_remote.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.campaign local_remote "$@"
