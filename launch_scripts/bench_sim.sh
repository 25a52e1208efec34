#!/usr/bin/env bash
# bench_sim.sh — benchmark the simulator and the navigation node; prints and saves the figures.
#
#   launch_scripts/bench_sim.sh [--out DIR]        (default DIR: bench_results)
#
# Measures: simulator core real-time multiple without ROS (corridor, data-center), time per 640-beam
# scan and per 80x60 depth frame, achieved real-time factor of the simulator node with ROS I/O as fast as
# possible, time to plan across the data-center hall, navigation control-loop time, time to put a depth
# frame into the local costmap, the depth stream's bandwidth and move_base's CPU per depth frame (the robot
# brought up twice in real time, with and without the depth source: about 2.5 minutes), and what a move_base
# start-up costs the master (parameter calls, registrations). Writes DIR/sim.json, navigation.json,
# depth.json, move_base_startup.json and the table DIR/bench_sim.md. Uses private rosmasters on free ports;
# stops everything it starts.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
out="$CNR_WS/bench_results"
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$(realpath -m "${2:?}")"; shift 2 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) cnr_die "unknown argument '$1' (see --help)" ;;
  esac
done
"$CNR_WS/launch_scripts/setup.sh" --no-install >/dev/null
cnr_source_ws
mkdir -p "$out"
cnr_log "simulator (cnr_sim.bench)"
/usr/bin/python3 -m cnr_sim.bench --out "$out/sim.json"
cnr_log "navigation (cnr_navigation.bench)"
/usr/bin/python3 -m cnr_navigation.bench --out "$out/navigation.json"
cnr_log "depth stream bandwidth and move_base CPU per depth frame (cnr_benchmarks.depth)"
/usr/bin/python3 -m cnr_benchmarks.depth --out "$out/depth.json"
cnr_log "move_base start-up on the master (cnr_navigation.startup_audit)"
/usr/bin/python3 -m cnr_navigation.startup_audit --out "$out/move_base_startup.json"
/usr/bin/python3 - "$out" <<'PY'
import json, os, sys, platform
out = sys.argv[1]
rows = [r for name in ('sim.json', 'navigation.json', 'depth.json') for r in json.load(open(os.path.join(out, name)))]
s = json.load(open(os.path.join(out, 'move_base_startup.json')))
def ok(value, target):
    if target in ('-', '') or target.split()[0] not in ('>=', '<='):
        return ''
    op, num = target.split()
    return 'pass' if (value >= float(num) if op == '>=' else value <= float(num)) else 'FAIL'
lines = ['| quantity | measured | target | |', '|---|---|---|---|']
for r in rows:
    lines.append(f"| {r['name']} | {r['value']:.2f} {r['unit']} | {r['target']} | {ok(r['value'], r['target'])} |")
lines.append(f"| move_base start-up: parameter calls | {s['parameter_calls']} | about 390 (TurtleBot move_base) | |")
lines.append(f"| move_base start-up: registrations | {s['registrations']} | about 50 | |")
lines.append(f"| move_base start-up time (local master) | {s['startup_seconds']:.2f} s | - | |")
text = '\n'.join(lines) + f"\n\nMachine: {platform.machine()}, {os.cpu_count()} cores; command: launch_scripts/bench_sim.sh\n"
open(os.path.join(out, 'bench_sim.md'), 'w').write(text)
print(text)
PY
cnr_log "wrote $out/bench_sim.md"
