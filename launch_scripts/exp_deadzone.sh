#!/usr/bin/env bash
# exp_deadzone.sh — the paper's dead-zone experiment (thesis Appendix VI, root), page in docs/results/deadzone
# (entry point cnr_benchmarks.deadzone; options: exp_deadzone.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.deadzone "$@"
