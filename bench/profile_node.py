#!/usr/bin/env python
"""The estimator node under cProfile (not a test; started by ``bench/bench_live_scale.py --profile``).

``python bench/profile_node.py OUT.prof --ros-args ...``: runs the estimator exactly as its entry
point does (:func:`switchobs_ros.runner.run_node`), with cProfile enabled at the node's first input message
(start-up, table loading and the idle wait for the sender left out: what a CPU per answer counts
from the first tick), and writes the statistics to
``OUT.prof`` at exit (SIGINT). Read them with ``python -m pstats OUT.prof`` or
:func:`summary`. The clock is the thread's CPU time (waits and descheduling do not count; the
middleware's own threads are not seen). cProfile adds its own cost to every Python call, so the
totals are larger than the node's CPU without it; the shares are what it is for.
"""

from __future__ import annotations

import cProfile
import os
import pstats
import sys
import time
from pathlib import Path

#: The checkout whose estimator runs (``SWITCHOBS_PROFILE_REPO``; default: this one).
sys.path.insert(0, os.environ.get("SWITCHOBS_PROFILE_REPO") or str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from first_input import at_first_input  # bench/first_input.py


def summary(path: str | Path, k: int = 30, sort: str = "tottime") -> None:
    """Print the ``k`` costliest functions of a dump (by own time, or ``sort``)."""
    pstats.Stats(str(path)).sort_stats(sort).print_stats(k)


def main() -> int:
    out = Path(sys.argv[1])
    from switchobs_ros.estimator import EstimatorNode
    from switchobs_ros.runner import run_node

    prof = cProfile.Profile(time.thread_time)      # CPU of the node's thread, not wall time

    class ProfiledEstimator(EstimatorNode):
        """The estimator, profiled from its first input message (start-up and idle wait left out)."""

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            at_first_input(self.pipeline, prof.enable)

    try:
        return run_node(ProfiledEstimator, "estimator", [sys.argv[0], *sys.argv[2:]])
    finally:
        prof.disable()
        prof.dump_stats(str(out))


if __name__ == "__main__":
    sys.exit(main())
