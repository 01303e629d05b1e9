"""A ROS_DOMAIN_ID of our own, and the localhost-only discovery setting.

Every process here that starts a ROS node runs with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (else DDS multicasts out of the machine) and a
``ROS_DOMAIN_ID`` that no concurrent run uses. A run claims an id by holding an exclusive
``flock`` on ``$TMPDIR/switchobs-ros-domain-<id>.lock`` for its lifetime; the shell scripts
use the same lock files (scripts/lib.sh), so tests, demo and benchmark never share a domain.

``python -m tools.domain`` prints a free id (without holding it: for humans).
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
from pathlib import Path

__all__ = ["DomainLease", "claim_domain", "localhost_env"]

#: Domain ids usable on Linux with the default port mapping (0 and 101 left to others).
DOMAIN_IDS = tuple(range(1, 101))


class DomainLease:
    """A claimed domain id; the claim lasts until :meth:`release` or process exit."""

    def __init__(self, domain_id: int, fh):
        self.domain_id = domain_id
        self._fh = fh

    def release(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _lock_path(i: int) -> Path:
    return Path(tempfile.gettempdir()) / f"switchobs-ros-domain-{i}.lock"


def claim_domain(seed: int | None = None) -> DomainLease:
    """Claim a free domain id (random order, first one whose lock file is free)."""
    ids = list(DOMAIN_IDS)
    random.Random(seed if seed is not None else os.getpid()).shuffle(ids)
    for i in ids:
        fh = open(_lock_path(i), "a")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        return DomainLease(i, fh)
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..100 (all lock files are held)")


def localhost_env(domain_id: int, base: dict | None = None) -> dict:
    """A copy of ``base`` (default ``os.environ``) with localhost discovery and the domain id."""
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(int(domain_id))
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy; RANGE takes precedence anyway
    env.pop("ROS_STATIC_PEERS", None)
    return env


if __name__ == "__main__":
    lease = claim_domain()
    print(lease.domain_id)
