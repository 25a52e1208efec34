#!/usr/bin/env bash
# bench_migration.sh — migration downtime and failover on the testbed (root), page in docs/results/migration_<mode>
# (entry point cnr_benchmarks.migration_bench; options: bench_migration.sh --help).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_python cnr_benchmarks.migration_bench "$@"
