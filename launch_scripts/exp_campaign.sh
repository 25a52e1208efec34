#!/usr/bin/env bash
# exp_campaign.sh — the continuous experiment of thesis §5: --conditions link conditions (default
# 100; RTT 0-200 ms, rate 0.5-50 Mbit/s log-uniform, loss 0-5 %, drawn with --seed) on the two-host testbed, each
# profiled once with move_base on the robot and decided by network_monitor's migration_decider (k-NN), then run
# onload and offload on that profile; both runs evaluated (Eq. 4-5) and learned from an empty training set.
# Then the analysis: the decisions against the oracle of the paired runs, the learning curve beside the best
# static threshold, and Figures 5-1 to 5-6 beside the thesis's numbers (bench_results/campaign/campaign.md). Needs the control values
# (exp_control.sh) and root; uses the default testbed. Rows are appended as measured; run it again to resume.
# About 66 s per condition (100 conditions in 1.83 h, 2026-11-26). --slowdown S: the robot's CPU capped at 1/S
# instead of config/testbed.yaml's (a copy of config/ in <out>/slowdown_<S>), with the control values of
# exp_control.sh --slowdown S (docs/results/control/control_values_slowdown<S>.yaml).
#
#   launch_scripts/exp_campaign.sh [--conditions 100] [--seed 1] [--out DIR] [--test-fraction 0.3]
#                                  [--rtt-min 0 --rtt-max 200 --rate-min 0.5 --rate-max 50 --loss-min 0
#                                   --loss-max 0.05] [--settle 6] [--port 11411] [--slowdown S]
#   launch_scripts/exp_campaign.sh --analyse-only [--out DIR] [--exclude c0017,...]   # the analysis and figures
#                                  of the rows so far (--exclude: conditions left out, named in campaign.md)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
cmd=campaign
if [ "${1:-}" = --analyse-only ]; then cmd=analyse; shift; fi
if [ "$cmd" = campaign ]; then
  [ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces and TUN devices)"
fi
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.campaign "$cmd" "$@"
