#!/usr/bin/env bash
# bench_migration.sh — migration downtime on the testbed: the two-host mission with --migration
# (every managed module starts on the robot), a probe on the robot recording each module's output and the
# instance it came from, and for each link RTT (default 0, 50, 100 ms) x module (move_base,
# local_mapcell_manager, global_goal_manager, mfg) x mode (cold, hot): --runs round trips robot -> cloud ->
# robot (default 10). Then per module --cutoff-trials times: the module on the cloud, the link cut, the time
# until the robot's instance is promoted and its output is back. Reports, on the robot's consumer, the
# downtime (the old instance closed its outputs -> the new one's first output; for local_mapcell_manager the
# longest a measurement waited for a store) and the gap (last old output -> first new output, the module's
# own output period included), median, p95 and max; the manager's hand-over time; measurements lost and goals
# aborted. Needs root; uses the default testbed (robot/cloud namespaces), so run nothing else on it meanwhile.
# Writes bench_results/migration/ results.tsv, failover.tsv (rows appended as measured) and migration.md.
# Takes about an hour with the defaults (cold migrations wait for the clone to start on the capped robot).
#
#   launch_scripts/bench_migration.sh [--runs 10] [--rtts 0,50,100] [--modules a,b] [--modes cold,hot]
#                                     [--cutoff-trials 3] [--settle 3] [--out DIR] [--port 11411]
#                                     [--config-dir DIR]   (default config/; e.g. a copy with robot_cpu off)
#                                     [--slowdown S]       (the robot capped at 1/S CPU, on a copy in --out)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.migration_bench "$@"
