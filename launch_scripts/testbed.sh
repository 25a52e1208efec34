#!/usr/bin/env bash
# testbed.sh — robot and cloud network namespaces joined by a user-space link emulator (needs root)
# (entry point cnr_testbed.cli; commands and options: testbed.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
[ -f "$CNR_WS/devel/setup.bash" ] || "$CNR_WS/launch_scripts/setup.sh" >/dev/null
cnr_python cnr_testbed.cli "$@"
