#!/usr/bin/env bash
# testbed.sh — robot and cloud network namespaces joined by a user-space link emulator (needs root).
#
#   launch_scripts/testbed.sh up|down|status|set|trace|follow ...   (launch_scripts/testbed.sh --help)
#
# Examples:  testbed.sh up;  testbed.sh set --delay 25;  ip netns exec robot ping 10.77.0.2;  testbed.sh down
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
if [ ! -f "$CNR_WS/devel/setup.bash" ]; then "$CNR_WS/launch_scripts/setup.sh" >/dev/null; fi
cnr_source_ws
exec /usr/bin/python3 -m cnr_testbed.cli "$@"
