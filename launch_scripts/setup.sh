#!/usr/bin/env bash
# setup.sh — make this checkout a working ROS 1 catkin workspace (idempotent).
#
#   launch_scripts/setup.sh [--no-install] [--no-build]
#
# 1. installs the Debian packages the workspace needs that are missing (apt-get, needs root);
# 2. builds the workspace with catkin_make and Debian's /usr/bin/python3;
# Afterwards: `source devel/setup.bash`. The README's two commands call this first.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
WS="$CNR_WS"
install=1; build=1
for arg in "$@"; do
  case "$arg" in
    --no-install) install=0 ;;
    --no-build) build=0 ;;
    -h|--help) cnr_help; exit 0 ;;
    *) echo "setup.sh: unknown option '$arg' (see --help)" >&2; exit 2 ;;
  esac
done

# Debian 12 packages: ROS 1 from Debian, message packages, and the Python libraries (built for /usr/bin/python3).
PKGS=(
  ros-core catkin ros-message-generation python3-catkin-pkg python3-genmsg python3-genpy
  python3-rospy python3-rostest python3-roslaunch python3-rosnode python3-rostopic python3-rosservice
  python3-rosparam python3-rosmsg python3-rosgraph python3-rosbag
  python3-actionlib python3-tf2-ros python3-dynamic-reconfigure libdynamic-reconfigure-config-init-mutex-dev
  python3-message-filters python3-map-msgs
  libstd-msgs-dev libgeometry-msgs-dev libsensor-msgs-dev libnav-msgs-dev libactionlib-msgs-dev
  libmove-base-msgs-dev libtf2-msgs-dev
  python3-std-msgs python3-geometry-msgs python3-sensor-msgs python3-nav-msgs python3-std-srvs
  python3-move-base-msgs python3-actionlib-msgs python3-tf2-msgs python3-rosgraph-msgs
  python3-numpy python3-numba python3-scipy python3-skimage python3-yaml python3-psutil python3-pil
  python3-matplotlib python3-pytest python3-pytest-timeout python3-serial python3-pyroute2 python3-sklearn iproute2 iputils-ping iperf3
)

if [ "$install" = 1 ]; then
  missing=()
  for p in "${PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ "${#missing[@]}" -gt 0 ]; then
    echo "setup.sh: installing ${#missing[@]} missing Debian package(s): ${missing[*]}"
    if [ "$(id -u)" != 0 ]; then
      echo "setup.sh: need root to install packages (run as root or: sudo apt-get install ${missing[*]})" >&2
      exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup.sh: all ${#PKGS[@]} Debian packages present"
  fi
fi

if [ "$build" = 1 ]; then
  echo "setup.sh: building the catkin workspace in $WS"
  cd "$WS"
  log="$WS/build/catkin_make.log"
  mkdir -p "$WS/build"
  # one build at a time (several shells may call setup.sh at once)
  exec 9>"$WS/build/.setup.lock"; flock 9
  if ! catkin_make --source . -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=OFF >"$log" 2>&1; then
    tail -n 40 "$log" >&2
    echo "setup.sh: catkin_make failed (full log: $log)" >&2
    exit 1
  fi
  echo "setup.sh: workspace built; now: source $WS/devel/setup.bash"
fi
