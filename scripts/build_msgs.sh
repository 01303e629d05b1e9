#!/usr/bin/env bash
# Build the interface package interfaces/switchobs_msgs (ament_cmake + rosidl) and install it into
# the virtual environment's prefix, beside the ROS wheels: then `import switchobs_msgs` works and
# the ament index finds it (AMENT_PREFIX_PATH=$VENV) without sourcing a setup file.
# Called by scripts/bootstrap.sh when the interface files or the requirements changed; runnable
# alone. Needs cmake, g++, make and the Python headers (installed with apt-get when missing).
# Plain cmake rather than colcon: the wheels are an ament_cmake install tree without colcon's
# setup files, and `cmake --install` gives exactly that layout. On failure: one line naming the
# step and the log, exit 1.
set -euo pipefail
. "$(dirname "$0")/lib.sh"

PKG="$REPO/interfaces/switchobs_msgs"
WORK="$VENV/build/switchobs_msgs"
LOG="$VENV/build/switchobs_msgs.log"
MANIFEST="$VENV/build/switchobs_msgs.manifest"    # what the last install put into $VENV
PYBIN="$VENV/bin/python"

fail() { echo "bootstrap: switchobs_msgs build failed at $1 (log: $LOG)" >&2; exit 1; }

mkdir -p "$VENV/build"
: > "$LOG"

# 1. Toolchain: Debian's cmake, g++, make, python3-dev.
py_include="$("$PYBIN" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
if ! command -v cmake >/dev/null || ! command -v g++ >/dev/null || ! command -v make >/dev/null \
        || [ ! -f "$py_include/Python.h" ]; then
    echo "bootstrap: installing cmake g++ make python3-dev with apt-get"
    apt-get update >> "$LOG" 2>&1 || true     # a stale list may still serve; the install decides
    DEBIAN_FRONTEND=noninteractive apt-get install -y cmake g++ make python3-dev >> "$LOG" 2>&1 \
        || fail "apt-get install cmake g++ make python3-dev"
    [ -f "$py_include/Python.h" ] || fail "the Python headers ($py_include/Python.h missing)"
fi

# 2. The wheels bake the wheel build machine's Python and numpy include directories into their
#    exported rosidl_generator_py targets; point them at this environment's (redo after any
#    reinstall of the wheels: the next bootstrap does, since requirements.txt is in its stamp).
np_include="$("$PYBIN" -c 'import numpy; print(numpy.get_include())')"
sed -i -E "s#INTERFACE_INCLUDE_DIRECTORIES \"[^\"]*\"#INTERFACE_INCLUDE_DIRECTORIES \"$py_include;$np_include\"#" \
    "$VENV"/share/*/cmake/export_*__rosidl_generator_pyExport.cmake

# 3. Configure and build in a clean build directory, then install: the files of the previous
#    install are removed only once the new build has succeeded (a deleted message leaves nothing
#    behind; a failed build leaves the previous install working).
rm -rf "$WORK"
export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
cmake -S "$PKG" -B "$WORK" -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
    -DPython3_EXECUTABLE="$PYBIN" >> "$LOG" 2>&1 || fail "cmake configure"
cmake --build "$WORK" -j "$(nproc)" >> "$LOG" 2>&1 || fail "cmake build"
if [ -f "$MANIFEST" ]; then
    xargs -d '\n' rm -f < "$MANIFEST"
fi
cmake --install "$WORK" >> "$LOG" 2>&1 || fail "cmake install"
cp "$WORK/install_manifest.txt" "$MANIFEST"
"$PYBIN" -c "from switchobs_msgs.msg import ActiveChannel, ErrorBounds, StateEstimate" >> "$LOG" 2>&1 \
    || fail "import switchobs_msgs"
