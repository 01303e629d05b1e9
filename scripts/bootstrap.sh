#!/usr/bin/env bash
# Create or update the project's virtual environment from requirements.txt (idempotent).
# Fast when nothing changed: a stamp of requirements.txt + setup.py skips pip entirely.
# Needs only Python 3.11 and network access to PyPI (Debian 12: python3; python3-venv is
# used if present, else virtualenv is installed with pip).
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

stamp="$VENV/.switchobs-bootstrap"
want="$(cat "$REPO/requirements.txt" "$REPO/setup.py" "$REPO/setup.cfg" | sha256sum | cut -d' ' -f1)"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ -x "$VENV/bin/estimator" ] \
        && "$VENV/bin/python" -c "import rclpy, cvxpy, switchobs_ros" 2>/dev/null; then
    exit 0
fi
echo "bootstrap: installing requirements.txt into $VENV"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet -r "$REPO/requirements.txt"
"$VENV/bin/python" -m pip install --quiet --no-deps --no-build-isolation -e "$REPO"
"$VENV/bin/python" -c "import rclpy, cvxpy, switchobs_core, msg_bridge, switchobs_ros"
echo "$want" > "$stamp"
echo "bootstrap: done"
