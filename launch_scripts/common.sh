# common.sh — sourced by every launch_script: its --help text, log and error lines, and the workspace
# environment. Not executable on its own; sourcing it only defines variables and functions.
#
# The user scripts are thin wrappers over one Python entry point each (cnr_python): the entry point parses
# the options (its --help), resolves the master address, starts what it needs in process groups of its own
# and stops them when it ends (cnr_harness.script).

CNR_WS="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

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

# cnr_python MODULE [ARGS...]: the script's Python entry point (MODULE's __main__) in the sourced workspace.
cnr_python() {
  local module="$1"; shift
  cnr_source_ws
  exec /usr/bin/python3 -m "$module" "$@"
}
