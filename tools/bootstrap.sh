#!/usr/bin/env bash
# Set up (or reuse) a local environment and build the package with colcon.
#   tools/bootstrap.sh [latest|apt]
# latest: .venv with the newest numpy/scipy/OpenCV, build into build/ and install/.
# apt:    .venv-apt with Ubuntu 24.04's versions (numpy 1.26, scipy 1.11, OpenCV 4.6),
#         build into build-apt/ and install-apt/.
# A second run reuses what is there: pip runs only when a requirements file changed,
# colcon only when packaging files or the module list changed.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
profile="${1:-latest}"
case "$profile" in
  latest) venv="$root/.venv"; build="$root/build"; install="$root/install" ;;
  apt) venv="$root/.venv-apt"; build="$root/build-apt"; install="$root/install-apt" ;;
  *) echo "bootstrap: unknown profile '$profile' (latest or apt)" >&2; exit 2 ;;
esac
cd "$root"
exec 9>"$root/.bootstrap-$profile.lock"
flock 9

python="${PYTHON:-python3}"
if ! "$python" -c 'import sys; sys.exit(0 if sys.version_info[:2] >= (3, 10) else 1)'; then
  echo "bootstrap: need Python >= 3.10 (ROS 2 Jazzy wheels are built for 3.11/3.12)" >&2
  exit 2
fi
req_hash=$(cat tools/requirements-ros.txt "tools/requirements-$profile.txt" | sha256sum | cut -c1-16)
if [ ! -f "$venv/.accelcal-req" ] || [ "$(cat "$venv/.accelcal-req")" != "$req_hash" ]; then
  echo "bootstrap: creating $venv (ROS 2 Jazzy wheels, colcon, $profile numeric stack)"
  if ! "$python" -m venv --clear "$venv" 2>/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
      "$python" -m venv --clear "$venv"
    else
      echo "bootstrap: '$python -m venv' failed; install python3-venv" >&2; exit 2
    fi
  fi
  # (this machine's pip configuration names local indexes that may be absent: quiet them)
  "$venv/bin/python" -m pip install -q --upgrade pip 2>&1 | grep -v '^WARNING: Location' || true
  "$venv/bin/python" -m pip install -q -r tools/requirements-ros.txt \
      -r "tools/requirements-$profile.txt" 2>&1 | grep -v '^WARNING: Location' || true
  "$venv/bin/python" -c 'import rclpy, numpy, scipy, cv2, yaml, smbus2, colcon_core' || {
    echo "bootstrap: installing into $venv failed (see pip's messages above)" >&2; exit 1; }
  touch "$venv/COLCON_IGNORE"
  echo "$req_hash" > "$venv/.accelcal-req"
fi

# tf2_msgs is no PyPI wheel: generate its TFMessage (tools/interfaces/tf2_msgs, the same
# definition and type hash as ROS 2's) with the rosidl wheels into the same install/.
# Needs a C/C++ compiler and the Python headers (installed here as root with apt-get, as
# python3-venv above); rebuilt only when the interface files or the venv changed.
tf2_hash=$( { echo "$req_hash"; find tools/interfaces -type f | sort;
             find tools/interfaces -type f | sort | xargs cat; } | sha256sum | cut -c1-16)
if [ ! -f "$install/.accelcal-tf2_msgs" ] || [ "$(cat "$install/.accelcal-tf2_msgs")" != "$tf2_hash" ]; then
  need=()
  command -v c++ >/dev/null && command -v cc >/dev/null || need+=(g++)
  "$venv/bin/python" -c 'import os, sysconfig, sys
sys.exit(0 if os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")) else 1)' \
    || need+=(python3-dev)
  if [ ${#need[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      apt-get update -qq && apt-get install -y -qq "${need[@]}" >/dev/null
    else
      echo "bootstrap: building tf2_msgs needs ${need[*]} (apt-get install ${need[*]})" >&2; exit 2
    fi
  fi
  echo "bootstrap: generating tf2_msgs ($profile)"
  rm -rf "$build/tf2_msgs" "$install/tf2_msgs"
  ( source "$venv/bin/activate"
    export AMENT_PREFIX_PATH="$venv"  # where the generators' ament index is
    colcon --log-base "$root/log" build --paths "$root/tools/interfaces/tf2_msgs" \
        --build-base "$build" --install-base "$install" \
        --event-handlers console_cohesion- summary- >/dev/null 2>&1 ) || {
    echo "bootstrap: generating tf2_msgs failed; see $root/log/latest_build" >&2; exit 1; }
  echo "$tf2_hash" > "$install/.accelcal-tf2_msgs"
fi

# The two-host graph test (network namespaces) needs iproute2: install it only if missing
# and root (it is skipped, with the reason, where it cannot run).
if ! command -v ip >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  apt-get update -qq && apt-get install -y -qq iproute2 >/dev/null \
    || echo "bootstrap: could not install iproute2; the two-host test will be skipped" >&2
fi

# colcon: rebuild only when what it installs changed (sources are symlinked).
build_hash=$( { cat setup.py setup.cfg package.xml; ls config launch resource;
                find accelcal_ros -name '*.py' | sort; } | sha256sum | cut -c1-16)
if [ ! -f "$install/.accelcal-build" ] || [ "$(cat "$install/.accelcal-build")" != "$build_hash" ]; then
  echo "bootstrap: colcon build ($profile)"
  ( source "$venv/bin/activate"
    colcon --log-base "$root/log" build --paths "$root" --symlink-install \
        --build-base "$build" --install-base "$install" \
        --event-handlers console_cohesion- summary- >/dev/null ) || {
    echo "bootstrap: colcon build failed; see $root/log/latest_build" >&2; exit 1; }
  echo "$build_hash" > "$install/.accelcal-build"
fi
