#!/usr/bin/env python
"""The estimator node with its CPU accumulated by phase (not a test; started by
``bench/bench_live_scale.py --phases``).

``python bench/phase_node.py OUT.json --ros-args ...``: runs the estimator exactly as its entry
point does (:func:`switchobs_ros.runner.run_node`), with :mod:`bench.phases`' wrappers installed
before the node is built and their sums zeroed at its first input message (start-up and the wait for
the sender left out: ``bench/first_input.py``), and writes
:func:`phases.report <phases.report>` to ``OUT.json`` at exit (SIGINT). The clock is the spinning
thread's CPU time (the middleware's threads are not seen).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The checkout whose estimator runs (``SWITCHOBS_PROFILE_REPO``; default: this one).
sys.path.insert(0, os.environ.get("SWITCHOBS_PROFILE_REPO") or str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import phases  # bench/phases.py, after the checkout is on the path
from first_input import at_first_input


def main() -> int:
    out = Path(sys.argv[1])
    phases.install()
    from switchobs_ros.estimator import EstimatorNode
    from switchobs_ros.runner import run_node

    class PhasedEstimator(EstimatorNode):
        """The estimator, its phases counted from its first input message."""

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            at_first_input(self.pipeline, phases.start)

    try:
        return run_node(PhasedEstimator, "estimator", [sys.argv[0], *sys.argv[2:]])
    finally:
        phases.report(path=out)


if __name__ == "__main__":
    sys.exit(main())
