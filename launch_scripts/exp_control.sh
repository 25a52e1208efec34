#!/usr/bin/env bash
# exp_control.sh — the control experiment of thesis Table 4-5: --runs runs (default 20) of the task
# (default corridor_round_trip@corridor: config/scenarios/corridor.yaml tasks) on the two-host testbed with every
# module on the robot and no decision; CT (task time) and CB (battery fraction) as mean and sd of the completed
# runs are written to config/control_values.yaml (Eq. 4-5's control values) and printed beside the thesis's
# CT 87.9286 s (sd 14.3815), CB 0.004586 (sd 0.000702). Needs root; uses the default testbed (robot/cloud
# namespaces). Rows go to bench_results/control/<task>@<location>/results.tsv as measured; run it again to
# resume. --task patrol (or hotspot_search: a monitoring mission of config/decision.yaml, the main job's
# decision) runs whole two-host missions instead, as the main job measures them (T to the hotspot, B until
# then), with the link of --link-map (default config/link_map_<location>.yaml); about 4 minutes each.
#
# --slowdown S measures them with the robot's CPU capped at 1/S (default config/testbed.yaml's robot_cpu.slowdown):
# written to docs/results/control/control_values_slowdown<S>.yaml, rows in bench_results/control/<task>@<location>_slowdown<S>.
# --from-rows FILE runs nothing: the control values of the all-local runs of a results TSV, e.g. the onload runs
# of exp_local_remote.sh (bench_results/local_remote/slowdown_<S>/results.tsv: the same task, every module local).
#
#   launch_scripts/exp_control.sh [--runs 20] [--task T] [--location L] [--out DIR] [--control-values FILE]
#                                 [--settle 6] [--port 11411] [--link-map FILE] [--slowdown S]
#                                 [--from-rows FILE]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.campaign control "$@"
