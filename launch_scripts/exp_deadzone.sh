#!/usr/bin/env bash
# exp_deadzone.sh — the paper's dead-zone experiment (thesis Appendix VI, Fig. 10-11), on the testbed (root).
#
#   launch_scripts/exp_deadzone.sh [--runs N] [--modes normal,network_aware[,normal_uplink]] [--out DIR] [--fresh]
#
# The corridor (config/scenarios/deadzone.yaml: 2 m x 12 m, a pair of heaters, the global goal module's Z
# route) with Wi-Fi only near both ends (the link follows the robot's position); N runs per mode (default 5),
# alternating (default modes normal and network_aware):
#   normal         GG and MFG on the cloud (placement paper_normal), dead zone cuts both directions
#                  (config/link_map_corridor.yaml)
#   network_aware  GG on the cloud, MFG on the robot (paper_network_aware), the same dead zone
#   normal_uplink  as normal, but the dead zone cuts robot -> cloud only (config/link_map_corridor_uplink.yaml):
#                  the paper's own description of its normal run ("sensor data does not reach the MFG")
# Each run is a real-time two-host mission (run_mission.sh --two-host) with its report in
# DIR/runs/<mode>-<i>/ and its output in DIR/runs/<mode>-<i>.log (default DIR bench_results/deadzone). Resumable: a run whose summary.json exists is
# kept (--fresh starts over). Then DIR/runs.tsv, DIR/deadzone.md (time and measurements to the hotspot,
# median and spread, beside the paper's ~100 measurements / ~33 s; the MFG's longest idle time) and
# DIR/deadzone.png (temperature vs measurement number, the paper's plot). About 2 minutes per run.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
runs=5; out="$CNR_WS/bench_results/deadzone"; fresh=""; modes="normal,network_aware"
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs="${2:?}"; shift 2 ;;
    --modes) modes="${2:?}"; shift 2 ;;
    --out) out="$(realpath -m "${2:?}")"; shift 2 ;;
    --fresh) fresh=1; shift ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || cnr_die "--runs must be a positive integer, got '$runs'"
[ "$(id -u)" = 0 ] || cnr_die "needs root (the testbed: network namespaces, TUN devices, cgroups)"
"$CNR_WS/launch_scripts/setup.sh" >/dev/null
cnr_source_ws
[ -z "$fresh" ] || rm -rf "$out/runs"
mkdir -p "$out/runs"
IFS=, read -r -a mode_list <<< "$modes"
for mode in "${mode_list[@]}"; do
  case "$mode" in normal|network_aware|normal_uplink) ;; *) cnr_die "unknown mode '$mode' (normal, network_aware, normal_uplink)" ;; esac
done
total=$((${#mode_list[@]} * runs)); done_n=0; t0=$(date +%s)
for i in $(seq 1 "$runs"); do
  for mode in "${mode_list[@]}"; do
    case "$mode" in
      normal) placement=paper_normal; link_map=link_map_corridor.yaml ;;
      network_aware) placement=paper_network_aware; link_map=link_map_corridor.yaml ;;
      normal_uplink) placement=paper_normal; link_map=link_map_corridor_uplink.yaml ;;
    esac
    dir="$out/runs/$(printf '%s-%02d' "$mode" "$i")"
    done_n=$((done_n + 1))
    if [ -f "$dir/summary.json" ]; then
      cnr_log "[$done_n/$total] $mode run $i: done before, kept"
      continue
    fi
    rm -rf "$dir"; mkdir -p "$(dirname "$dir")"
    cnr_log "[$done_n/$total] $mode run $i ($placement), $(( $(date +%s) - t0 )) s so far"
    set +e
    "$CNR_WS/launch_scripts/run_mission.sh" --two-host --scenario deadzone --placement "$placement" \
      --link-map "$CNR_WS/config/$link_map" --report-dir "$dir" > "$dir.log" 2>&1
    status=$?
    set -e
    case "$status" in
      0|3) grep -h "hotspot found in\|timeout after" "$dir.log" | tail -1 || true ;;
      130) cnr_log "interrupted"; exit 130 ;;
      *) cnr_log "$mode run $i failed (status $status; see $dir.log)"; rm -f "$dir/summary.json" ;;
    esac
  done
done
rosrun cnr_mission deadzone_report --out "$out" --runs "$runs" --modes "$modes" \
  --command "launch_scripts/exp_deadzone.sh --runs $runs --modes $modes"
cnr_log "done in $(( $(date +%s) - t0 )) s: $out/deadzone.md, $out/deadzone.png, $out/runs.tsv"
