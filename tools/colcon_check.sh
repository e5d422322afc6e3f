#!/usr/bin/env bash
# Builds the package with colcon, as on a real Jazzy install, in a scratch workspace, and checks
# that `ros2 run` would find every executable where colcon puts them.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=$(cd "${VENV:-.venv}" && pwd)
"$VENV/bin/python" -m pip install -q colcon-common-extensions
ws=$(mktemp -d)
trap 'rm -rf "$ws"' EXIT
mkdir -p "$ws/src/tof_calib_ros"
git ls-files -z --cached --others --exclude-standard | tar --null -T - -cf - | tar -xf - -C "$ws/src/tof_calib_ros"
(cd "$ws" && PATH="$VENV/bin:$PATH" colcon build --packages-select tof_calib_ros >"$ws/build.log" 2>&1) \
  || { cat "$ws/build.log"; echo "colcon build failed"; exit 1; }
for exe in calibration_node tof_sim_node tof_calib; do
  path="$ws/install/tof_calib_ros/lib/tof_calib_ros/$exe"
  [ -x "$path" ] || { echo "colcon build: $path missing or not executable"; exit 1; }
done
[ -f "$ws/install/tof_calib_ros/share/ament_index/resource_index/packages/tof_calib_ros" ] \
  || { echo "colcon build: tof_calib_ros is not in the ament index"; exit 1; }
echo "colcon build: ok (calibration_node, tof_sim_node, tof_calib in install/tof_calib_ros/lib/tof_calib_ros)"
