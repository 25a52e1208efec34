#!/usr/bin/env bash
# exp_control.sh — the control experiment of thesis Table 4-5 (root), page in docs/results/control/<task>@<location>
# (entry point cnr_benchmarks.campaign control; options: exp_control.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.campaign control "$@"
