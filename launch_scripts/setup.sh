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

# Debian 12 packages, complete without Recommends (checked in a pristine Debian 12 root file system by
# ../shared/tools/fresh-machine-check, which .ci/run runs). Grouped by why they are needed.
PKGS=(
  # build: catkin_make runs CMake, whose project() needs a C++ compiler and make even for Python packages
  catkin make g++ catkin-lint
  # ROS 1 tools: master, roslaunch, rostopic/rosservice/rosnode/rosparam/rosbag (ros-core), rosrun (rosbash,
  # only recommended by ros-core), message generation and runtime, rostest
  ros-core rosbash ros-message-generation ros-message-runtime python3-rostest
  # the Python client libraries our nodes import
  python3-rospy python3-roslaunch python3-rosgraph python3-actionlib python3-tf2-ros python3-message-filters
  python3-dynamic-reconfigure libdynamic-reconfigure-config-init-mutex-dev
  # messages: Debian splits each into the definitions (ros-*, the .msg files genmsg reads), the CMake
  # config (lib*-dev, for find_package) and the generated Python (python3-*)
  ros-std-msgs libstd-msgs-dev python3-std-msgs
  ros-std-srvs libstd-srvs-dev python3-std-srvs
  ros-geometry-msgs libgeometry-msgs-dev python3-geometry-msgs
  ros-sensor-msgs libsensor-msgs-dev python3-sensor-msgs
  ros-nav-msgs libnav-msgs-dev python3-nav-msgs
  ros-actionlib-msgs libactionlib-msgs-dev python3-actionlib-msgs
  ros-move-base-msgs libmove-base-msgs-dev python3-move-base-msgs
  ros-tf2-msgs libtf2-msgs-dev python3-tf2-msgs
  ros-rosgraph-msgs python3-rosgraph-msgs python3-map-msgs
  # Python libraries (Debian's, built for /usr/bin/python3)
  python3-numpy python3-numba python3-scipy python3-skimage python3-sklearn python3-yaml python3-psutil
  python3-pil python3-matplotlib python3-serial python3-pyroute2 python3-pytest python3-pytest-timeout python3-pytest-xdist
  python3-netifaces
  # the testbed: network namespaces, ping, iperf3; pgrep
  iproute2 iputils-ping iperf3 procps
  # watching the mission (cnr_viz, run_mission.sh --view/--record): rviz and the markers' messages, a virtual
  # display and Mesa's software GL for rviz without a screen (its test), the screenshot's X client
  # (python3-xlib); rosbag comes with ros-core
  rviz ros-visualization-msgs python3-visualization-msgs xvfb libgl1-mesa-dri python3-xlib
)

missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "$install" = 0 ] && [ "${#missing[@]}" -gt 0 ]; then
  # the scripts other than the README's two commands call setup.sh --no-install: say what to do, not
  # "catkin_make: command not found"
  echo "setup.sh: ${#missing[@]} Debian package(s) the workspace needs are missing (${missing[*]:0:5} ...):" \
       "run launch_scripts/setup.sh once as root to install them" >&2
  exit 1
fi
if [ "$install" = 1 ]; then
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
