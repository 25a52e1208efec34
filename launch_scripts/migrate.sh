#!/usr/bin/env bash
# migrate.sh — ask the migration manager to move a module between the robot and the cloud, or show where
# each module runs (entry point migration_manager.cli; options: migrate.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
cnr_python migration_manager.cli "$@"
