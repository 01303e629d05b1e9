#!/usr/bin/env bash
# The demo: estimator and camera_sim as separate processes over DDS on localhost, 30 s of
# simulated time on the paper's periodic (2 s, 0.6) schedule; prints ||x_hat - x|| per cycle
# and writes out/demo/error.png. Options are passed on: --schedule sequence, --duration S,
# --time-scale K, --init zeros, --out DIR (see `python -m tools.demo --help`).
set -euo pipefail
"$(dirname "$0")/bootstrap.sh"
. "$(dirname "$0")/lib.sh"
claim_ros_domain
export SWITCHOBS_CLAIM_DOMAIN=0
cd "$REPO"
exec "$VENV/bin/python" -m tools.demo "$@"
