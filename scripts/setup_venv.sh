#!/usr/bin/env bash
# Create (or refresh) the project's virtual environment: ROS 2 Jazzy from the PyPI wheels, the project's
# Python dependencies (requirements.txt), hindrax_msgs built with rosidl and installed into the venv, and
# the two Python packages installed in editable mode. Called by `make setup`; safe to re-run.
# Facts this relies on: docs/architecture.md §11.2.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST

ver=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
if [ "$ver" != "3.11" ]; then
  echo "setup: ROS 2 Jazzy wheels need CPython 3.11 (found $ver at $(command -v "$PYTHON")); set PYTHON=python3.11" >&2
  exit 1
fi
arch=$(uname -m)
if [ "$arch" != "x86_64" ]; then
  echo "setup: the ros-jazzy-* wheels exist for x86_64 only (this is $arch). On the Raspberry Pi use ROS 2 Jazzy" \
       "from apt or the docker/ image and build ros_ws with colcon (README, 'Running on the Pi')." >&2
  exit 1
fi
for tool in cmake ninja; do
  if ! command -v $tool >/dev/null 2>&1; then
    echo "setup: $tool not found; installing it into the venv from PyPI" >&2
    NEED_BUILD_TOOLS=1
  fi
done

# Progress (2-3 minutes on a fresh machine): one line updated in place on a terminal, a line per step in a log.
STEPS=5
source scripts/progress.sh

step "Python venv $VENV"
SETUP_KIND=existing
[ -x "$VENV/bin/python" ] || { SETUP_KIND=new; "$PYTHON" -m venv "$VENV"; }
PY="$VENV/bin/python"
# pip, quiet, without the noise of index locations a machine's pip.conf may list but not have.
pipq() {
  "$PY" -m pip "$@" 2>&1 | { grep -v '^WARNING: Location .* is ignored' || true; }
  return "${PIPESTATUS[0]}"
}
step "ROS 2 Jazzy wheels and Python packages (pip, about 2 minutes on a fresh venv)"
ticking
pipq install -q --upgrade pip
# colcon too (requirements-colcon.txt): `make ros-install` builds ros_ws with it, and the test suite
# runs that build, which must not install packages into the venv while other tests run.
# --no-compile: pip would byte-compile every module of every wheel (the ROS wheels' generated
# interfaces of packages nothing here imports among them); the import check below compiles the
# libraries the tests import. A fresh venv's `make setup`, alternated with the pip byte-compile
# (2026-11-29, 2 cores, two rounds of two pairs): wall 0.95x and 0.89x, CPU 0.90x (149 against 165
# CPU-s); pip's own step 27 -> 14 CPU-s.
pipq install -q --no-compile -r requirements.txt -r requirements-colcon.txt -c constraints.txt
if [ "${NEED_BUILD_TOOLS:-0}" = 1 ]; then pipq install -q -c constraints.txt 'cmake>=3.22,<4' 'ninja>=1.11,<2'; fi
stop_ticking
export PATH="$PWD/$VENV/bin:$PATH"

# The wheels' rosidl_generator_py CMake exports hard-code the wheel build host's include directories;
# point them at this venv's Python and numpy headers (docs/architecture.md §11.2).
py_inc=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
np_inc=$("$PY" -c 'import numpy; print(numpy.get_include())')
{ grep -rlZ --include='*.cmake' -e '/opt/python/cp311-cp311' "$VENV/share" 2>/dev/null || true; } | \
  xargs -0 -r sed -i \
    -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#${np_inc}#g" \
    -e "s#/opt/python/cp311-cp311/include/python3.11#${py_inc}#g"

# Build and install hindrax_msgs into the venv prefix (importable with no environment variables), and
# third_party/tf2_msgs: a stand-in holding tf2_msgs/TFMessage, which the wheels lack (the vehicle's ROS has it).
step "interfaces hindrax_msgs and tf2_msgs (cmake, about 30 s)"
ticking
venv_abs=$(cd "$VENV" && pwd)
mkdir -p build
# hindrax_msgs compiles through ccache with the settings of scripts/ccache_env.sh: the suite's
# `make ros-install` (test/conftest.py) compiles the same generated sources and takes its objects
# from there (173 of 175 compiles).
. scripts/ccache_env.sh
for pkg_dir in src/hindrax_msgs third_party/tf2_msgs; do
  build=build/$(basename "$pkg_dir")
  launcher=()
  [ "$pkg_dir" != src/hindrax_msgs ] || launcher=(-DCMAKE_C_COMPILER_LAUNCHER="$venv_abs/bin/ccache"
                                                 -DCMAKE_CXX_COMPILER_LAUNCHER="$venv_abs/bin/ccache")
  cmake -S "$pkg_dir" -B "$build" -G Ninja -Wno-dev "${launcher[@]}" \
    -DCMAKE_PREFIX_PATH="$venv_abs" -DCMAKE_INSTALL_PREFIX="$venv_abs" \
    -DPython3_EXECUTABLE="$venv_abs/bin/python3" -DBUILD_TESTING=OFF >"$build.configure.log" 2>&1 \
    || { mkdir -p build; cat "$build.configure.log" >&2; exit 1; }
  cmake --build "$build" -j2 >"$build.build.log" 2>&1 || { cat "$build.build.log" >&2; exit 1; }
  cmake --install "$build" >/dev/null
done
unset PYTHONHASHSEED

stop_ticking
# The seven ament_python packages, editable (colcon builds the same setup.py on the Pi: common, drivers, bringup and
# onboard there).
step "hindrax_common, _drivers, _bringup, _onboard, _fit, _sim, _tools (editable)"
pipq install -q --no-deps --no-build-isolation -e src/hindrax_common -e src/hindrax_drivers -e src/hindrax_bringup \
  -e src/hindrax_onboard -e src/hindrax_fit -e src/hindrax_sim -e src/hindrax_tools >"build/editable-install.log" \
  || { cat build/editable-install.log >&2; exit 1; }

# Smoke check: the interfaces and rclpy import in the venv. It also byte-compiles the libraries
# every test worker imports (the pip step above compiles nothing), once here rather than by three
# workers at once; the rest (plots, the nodes' own modules) compiles at its first import.
step "import check"
PYTHONDONTWRITEBYTECODE= "$PY" -c 'import rclpy, tf2_msgs.msg, \
  hindrax_msgs.msg, hindrax_msgs.srv, hindrax_msgs.action, hindrax_common, hindrax_drivers, \
  hindrax_bringup, hindrax_onboard, hindrax_fit, hindrax_sim, hindrax_tools, scipy.optimize, \
  scipy.signal, scipy.stats, filterpy.kalman, mcap_ros2.decoder, rosbags.serde, pytest, xdist, \
  hypothesis'
progress_done
echo "setup: ready in $VENV ($((SECONDS - t0)) s)"
# The time into the measurements document the README quotes (RESULTS_DOC, from the Makefile): a warning if not.
if [ -n "${RESULTS_DOC:-}" ]; then
  "$PY" -m hindrax_tools.results_doc duration --results-doc "$RESULTS_DOC" "make setup ($SETUP_KIND .venv)" \
    $((SECONDS - t0)) || echo "setup: the time was not recorded in $RESULTS_DOC" >&2
fi
