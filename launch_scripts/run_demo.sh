#!/usr/bin/env bash
# run_demo.sh — README command (1): the navigation demo in the thesis's lab corridor
# (entry point cnr_bringup.demo; options: run_demo.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python cnr_bringup.demo "$@"
