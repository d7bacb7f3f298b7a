# Source this after tools/bootstrap.sh: activates the environment and the colcon install.
#   source tools/env.sh [latest|apt]
_accelcal_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
case "${1:-latest}" in
  apt) _venv="$_accelcal_root/.venv-apt"; _install="$_accelcal_root/install-apt" ;;
  *) _venv="$_accelcal_root/.venv"; _install="$_accelcal_root/install" ;;
esac
# shellcheck disable=SC1091
source "$_venv/bin/activate"
# colcon's setup.bash reads unset variables; relax nounset while sourcing it.
case $- in *u*) _nounset=1; set +u ;; *) _nounset= ;; esac
# shellcheck disable=SC1091
source "$_install/setup.bash"
[ -n "$_nounset" ] && set -u
export ACCELCAL_INSTALL="$_install"
# the node executables and `accelcal` (ament_python installs them in lib/<package>)
case ":$PATH:" in *":$_install/accelcal_ros/lib/accelcal_ros:"*) ;;
  *) export PATH="$_install/accelcal_ros/lib/accelcal_ros:$PATH" ;; esac
# the graph harness of the tests (test/graph_harness, not installed): the demo and the
# benchmarks drive node processes with it
case ":${PYTHONPATH:-}:" in *":$_accelcal_root/test:"*) ;;
  *) export PYTHONPATH="$_accelcal_root/test${PYTHONPATH:+:$PYTHONPATH}" ;; esac
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
unset _accelcal_root _venv _install _nounset
