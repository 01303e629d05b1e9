#!/usr/bin/env bash
# All tests: ruff check, then pytest. Arguments go to pytest: with none naming a test path
# (a file, a folder or a node id such as test/ros/test_x.py::test_y) pytest runs all of test/
# (core and ros); with one or more it runs just those (`scripts/test.sh test/core/design/test_plan.py`).
# `scripts/test.sh -m "not slow"` skips the DDS convergence runs and the colcon build.
# The ROS tests claim their own ROS_DOMAIN_ID (each pytest-xdist worker one of its own).
# The full run uses two pytest-xdist workers (SWITCHOBS_TEST_WORKERS, default 2; 1 = no xdist); a run
# naming test paths, or passing -n itself, runs as asked. The timed DDS runs (marker `serial`)
# run alone even then (test/conftest.py).
set -euo pipefail
"$(dirname "$0")/bootstrap.sh"
. "$(dirname "$0")/lib.sh"
claim_ros_domain
# The compiled kernel (bootstrap.sh builds it) is asked for where it can be built (an x86-64 machine
# with a C compiler): test_dense_kernel.py then fails without it. Elsewhere the numpy step runs and
# is what the tests check (set SWITCHOBS_REQUIRE_KERNEL to decide otherwise).
if [ -z "${SWITCHOBS_REQUIRE_KERNEL+set}" ]; then
    if [ "$(uname -m)" = x86_64 ] && command -v "${CC:-cc}" >/dev/null 2>&1; then
        export SWITCHOBS_REQUIRE_KERNEL=1
    else
        echo "test.sh: no C compiler for the x86-64 kernel here: the tests check the numpy step"
        export SWITCHOBS_REQUIRE_KERNEL=0
    fi
fi
cd "$REPO"
# Bytecode as an installed package has it: compiled once, under the venv (not in the checkout), and
# read by every test process. With PYTHONDONTWRITEBYTECODE set and no __pycache__ (a fresh clone),
# each of the suite's few hundred interpreters would compile the package again (~0.3 s each).
export PYTHONPYCACHEPREFIX="${PYTHONPYCACHEPREFIX:-$VENV/pycache}"
unset PYTHONDONTWRITEBYTECODE
echo "== ruff check"
"$VENV/bin/ruff" check .
echo "== pytest"
paths=()
skip_next=0
for a in "$@"; do
    if [ "$skip_next" = 1 ]; then skip_next=0; continue; fi
    case "$a" in
        -m|-k|-p|-c|-o|--rootdir|--deselect|--ignore|--junitxml|--maxfail|-W) skip_next=1 ;;  # takes a value
        -*) ;;
        *) if [ -e "${a%%::*}" ]; then paths+=("$a"); fi ;;
    esac
done
if [ "${#paths[@]}" -gt 0 ]; then
    exec "$VENV/bin/python" -m pytest "$@"
fi
workers=()
case " $* " in
    *" -n "*|*" -n"[0-9]*|*" --numprocesses"*|*" -p no:xdist "*|*" -pno:xdist "*) ;;
    *) if [ "${SWITCHOBS_TEST_WORKERS:-2}" -gt 1 ]; then
           workers=(-n "${SWITCHOBS_TEST_WORKERS:-2}" --dist load)
       fi ;;
esac
exec "$VENV/bin/python" -m pytest test "${workers[@]}" "$@"
