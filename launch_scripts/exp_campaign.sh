#!/usr/bin/env bash
# exp_campaign.sh — the continuous experiment of thesis §5 (root unless --analyse-only), page in docs/results/campaign
# (entry point cnr_benchmarks.campaign campaign; options: exp_campaign.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.campaign campaign "$@"
