# common.sh — sourced by every launch_script: --help text, workspace environment, master address,
# process start and cleanup. Not executable on its own. Sourcing it only defines variables and functions;
# the INT/TERM/EXIT traps that stop started processes are installed by the first cnr_spawn.
#
# Master address, in order of precedence: --host/--port arguments (parsed by each script),
# then ROS_MASTER_URI from the environment, then http://localhost:11311.

CNR_WS="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
CNR_PIDS=()

# Print the script's header comment (from line 2 to the first line that is not a comment) as its help.
cnr_help() { awk 'NR>1 && /^#/ {sub(/^# ?/, ""); print; next} NR>1 {exit}' "$0"; }

cnr_die() { echo "$(basename "$0"): $*" >&2; exit 2; }
cnr_log() { echo "[$(basename "$0")] $*"; }

# Source the built workspace (building it first if needed).
cnr_source_ws() {
  if [ ! -f "$CNR_WS/devel/setup.bash" ]; then
    "$CNR_WS/launch_scripts/setup.sh" || exit 1
  fi
  set +u; source "$CNR_WS/devel/setup.bash"; set -u
}

# cnr_master_uri HOST PORT -> sets ROS_MASTER_URI from arguments or environment.
cnr_master_uri() {
  local host="${1:-}" port="${2:-}"
  local env_uri="${ROS_MASTER_URI:-http://localhost:11311}"
  local env_hostport="${env_uri#http://}"; env_hostport="${env_hostport%/}"
  [ -n "$host" ] || host="${env_hostport%:*}"
  [ -n "$port" ] || port="${env_hostport##*:}"
  [[ "$port" =~ ^[0-9]+$ ]] && [ "$port" -ge 1 ] && [ "$port" -le 65535 ] || cnr_die "invalid master port '$port'"
  export ROS_MASTER_URI="http://$host:$port"
  CNR_MASTER_HOST="$host"; CNR_MASTER_PORT="$port"
}

cnr_master_up() {
  /usr/bin/python3 - "$ROS_MASTER_URI" <<'PY' >/dev/null 2>&1
import sys, xmlrpc.client, socket
socket.setdefaulttimeout(1.0)
sys.exit(0 if xmlrpc.client.ServerProxy(sys.argv[1]).getPid('/cnr_script')[0] == 1 else 1)
PY
}

# Start a process in its own process group and remember it for cleanup (installs the cleanup traps).
cnr_spawn() {
  if [ "${#CNR_PIDS[@]}" -eq 0 ]; then
    trap 'cnr_cleanup; exit 130' INT TERM
    trap 'cnr_cleanup' EXIT
  fi
  setsid "$@" &
  CNR_PIDS+=("$!")
}

# Start a rosmaster (roscore: master + rosout) on CNR_MASTER_PORT unless one answers already.
cnr_ensure_master() {
  if cnr_master_up; then
    cnr_log "using the running master at $ROS_MASTER_URI"
    return 0
  fi
  cnr_log "starting roscore on port $CNR_MASTER_PORT"
  cnr_spawn roscore -p "$CNR_MASTER_PORT"
  local i
  for i in $(seq 1 100); do
    cnr_master_up && return 0
    kill -0 "${CNR_PIDS[-1]}" 2>/dev/null || cnr_die "roscore failed to start on port $CNR_MASTER_PORT (port in use?)"
    sleep 0.2
  done
  cnr_die "no master answered at $ROS_MASTER_URI after 20 s"
}

# Stop everything this script started: SIGINT (as roslaunch does), then SIGTERM, then SIGKILL.
cnr_cleanup() {
  # Stop what this script started, newest first (nodes before their master): SIGINT, then TERM, then KILL.
  local pid sig n i
  trap - INT TERM EXIT
  local rev=()
  for ((i=${#CNR_PIDS[@]}-1; i>=0; i--)); do rev+=("${CNR_PIDS[$i]}"); done
  for pid in "${rev[@]}"; do
    for sig in INT TERM KILL; do
      kill -0 "$pid" 2>/dev/null || break
      kill -s "$sig" -- "-$pid" 2>/dev/null || kill -s "$sig" "$pid" 2>/dev/null || true
      for n in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.2; done
    done
  done
}
