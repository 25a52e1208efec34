#!/usr/bin/env bash
# exp_local_remote.sh — thesis Figs. 5-5 and 5-6: the task (default corridor_round_trip@corridor)
# --runs times with every module on the robot and --runs times with move_base on the cloud (alternating), on the
# unrestricted link, at each robot CPU slowdown of --slowdowns (default config/testbed.yaml's robot_cpu.slowdown
# and twice it: the thesis compared local CPU frequencies). Battery and time per task, mean and sd, beside the
# thesis's (remote −10 % battery, −2.4 s); bench_results/local_remote/local_remote.md and its figures. Needs root
# and no running testbed; rows are appended as measured (<out>/slowdown_<s>/results.tsv): run it again to resume.
# About 25 s per run.
#
#   launch_scripts/exp_local_remote.sh [--runs 20] [--slowdowns 3,6] [--out DIR] [--task T] [--location L]
#                                      [--port 11411]
#   launch_scripts/exp_local_remote.sh --analyse-only [--slowdowns 3,6] [--out DIR]   # table and figures only
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
case "${1:-}" in -h|--help) cnr_help; exit 0 ;; esac
if [ "${1:-}" != --analyse-only ]; then
  [ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed's network namespaces, TUN devices and CPU cgroup)"
fi
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
exec /usr/bin/python3 -m cnr_benchmarks.campaign local_remote "$@"
