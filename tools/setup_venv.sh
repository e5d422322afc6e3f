#!/usr/bin/env bash
# Creates (or refreshes) .venv with the package, the ROS 2 Jazzy wheels and the test tools.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
fi
rm -rf build ./*.egg-info  # a stale build/ would put deleted modules into the wheel
"$VENV/bin/python" -m pip install -q ".[ros,test]"
