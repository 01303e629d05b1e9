#!/usr/bin/env bash
# All tests: ruff check, then pytest over test/ (core and ros). Extra arguments go to pytest
# (e.g. `scripts/test.sh -m "not slow"`). The ROS tests claim their own ROS_DOMAIN_ID.
set -euo pipefail
"$(dirname "$0")/bootstrap.sh"
. "$(dirname "$0")/lib.sh"
claim_ros_domain
cd "$REPO"
echo "== ruff check"
"$VENV/bin/ruff" check .
echo "== pytest"
exec "$VENV/bin/python" -m pytest test "$@"
