#!/usr/bin/env bash
# Create or update the project's virtual environment from requirements.txt (idempotent).
# Fast when nothing changed: a stamp of requirements.txt + setup.py skips pip entirely, and one of
# interfaces/switchobs_msgs skips its build (scripts/build_msgs.sh: cmake, g++, make, python3-dev).
# Needs Python 3.11 and network access to PyPI (Debian 12: python3; python3-venv is used if
# present, else virtualenv is installed with pip), and Debian's packages for the build.
set -euo pipefail
. "$(dirname "$0")/lib.sh"
PY="${PYTHON:-python3}"

if [ ! -x "$VENV/bin/python" ]; then
    echo "bootstrap: creating $VENV"
    if ! "$PY" -m venv "$VENV" 2>/dev/null; then
        rm -rf "$VENV"
        echo "bootstrap: python -m venv unavailable (python3-venv missing); using virtualenv"
        "$PY" -m pip install --user --quiet virtualenv || "$PY" -m pip install --user --quiet --break-system-packages virtualenv
        "$PY" -m virtualenv --quiet "$VENV"
    fi
fi

# Two stamps: the Python packages (requirements.txt + setup.py + setup.cfg) and the interface
# package switchobs_msgs (its files, and the first stamp: reinstalled wheels need the rebuild's
# include-path fix again).
stamp="$VENV/.switchobs-bootstrap"
msgs_stamp="$VENV/.switchobs-msgs"
want="$(cat "$REPO/requirements.txt" "$REPO/setup.py" "$REPO/setup.cfg" | sha256sum | cut -d' ' -f1)"
msgs_want="$( (echo "$want"; cd "$REPO/interfaces/switchobs_msgs" \
    && cat package.xml CMakeLists.txt msg/*.msg) | sha256sum | cut -d' ' -f1)"
py_ok() { [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ -x "$VENV/bin/estimator" ]; }
msgs_ok() { [ -f "$msgs_stamp" ] && [ "$(cat "$msgs_stamp")" = "$msgs_want" ]; }
# The optional compiled kernel (switchobs_core/numerics/_dense_step.c, setup.py) built into the checkout,
# where tests, the demo and the node import it; built again (--force) unless the module imported is the
# one built from the source there (its SHA-256: python -m switchobs_core.numerics.dense_kernel), not by
# file times. Without a C compiler (or off x86-64) the numpy step runs: a line says so and where the
# compiler's messages are, nothing fails (scripts/test.sh asks for it: a test fails).
build_kernel() {
    local log="$REPO/build/kernel-build.log"
    (cd "$REPO" && "$VENV/bin/python" -W ignore -m switchobs_core.numerics.dense_kernel) && return 0
    mkdir -p "$REPO/build"
    (cd "$REPO" && "$VENV/bin/python" setup.py build_ext --inplace --force >"$log" 2>&1) || true
    (cd "$REPO" && "$VENV/bin/python" -W ignore -m switchobs_core.numerics.dense_kernel) \
        || echo "bootstrap: the compiled kernel did not build (its log: $log): the numpy step runs"
}
if py_ok && msgs_ok \
        && "$VENV/bin/python" -c "import rclpy, cvxpy, switchobs_ros, switchobs_msgs.msg" 2>/dev/null; then
    build_kernel
    exit 0
fi
if ! py_ok || ! "$VENV/bin/python" -c "import rclpy, cvxpy, switchobs_ros" 2>/dev/null; then
    echo "bootstrap: installing requirements.txt into $VENV"
    "$VENV/bin/python" -m pip install --quiet --upgrade pip
    "$VENV/bin/python" -m pip install --quiet -r "$REPO/requirements.txt"
    "$VENV/bin/python" -m pip install --quiet --no-deps --no-build-isolation -e "$REPO"
    "$VENV/bin/python" -c "import rclpy, cvxpy, switchobs_core, msg_bridge, switchobs_ros"
    echo "$want" > "$stamp"
    rm -f "$msgs_stamp"
fi
if ! msgs_ok || ! "$VENV/bin/python" -c "import switchobs_msgs.msg" 2>/dev/null; then
    echo "bootstrap: building interfaces/switchobs_msgs into $VENV"
    t0=$SECONDS
    bash "$REPO/scripts/build_msgs.sh"
    echo "bootstrap: switchobs_msgs built in $((SECONDS - t0)) s"
    echo "$msgs_want" > "$msgs_stamp"
fi
build_kernel
echo "bootstrap: done"
