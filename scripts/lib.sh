# Shared by the scripts: repository paths, the venv, and a ROS_DOMAIN_ID of our own.
# Source it: `. "$(dirname "$0")/lib.sh"`.

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${SWITCHOBS_VENV:-$REPO/.venv}"
export PATH="$VENV/bin:$PATH"

# Localhost-only DDS discovery: without it, discovery multicasts out of the machine.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_LOCALHOST_ONLY ROS_STATIC_PEERS
# Every participant announces itself every 0.5 s, not Fast DDS's 3 s: a node started after another
# finds it within 0.5 s (config/fastdds_discovery.xml says what was measured). A profile the user
# set is kept.
export FASTRTPS_DEFAULT_PROFILES_FILE="${FASTRTPS_DEFAULT_PROFILES_FILE:-$REPO/config/fastdds_discovery.xml}"

# Small matrices only: multi-threaded BLAS just contends for the cores (switchobs_core/threads.py).
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"

# Claim a ROS_DOMAIN_ID no concurrent run uses: an exclusive flock on a lock file held (fd kept
# open) for the life of this shell. Same lock files as tools/domain.py.
claim_ros_domain() {
    local id fd dir="${TMPDIR:-/tmp}"
    for id in $(shuf -i 1-100); do
        exec {fd}>"$dir/switchobs-ros-domain-$id.lock" || continue
        if flock -n "$fd"; then
            export ROS_DOMAIN_ID="$id"
            return 0
        fi
        exec {fd}>&-
    done
    echo "no free ROS_DOMAIN_ID in 1..100" >&2
    return 1
}
