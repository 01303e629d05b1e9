#!/usr/bin/env python
"""The estimator's console-script start (what :func:`switchobs_ros.entry.estimator` does), timed phase by phase.

Run by ``bench/bench_startup_phases.py`` with ``T0`` (the parent's ``time.monotonic()`` just before the
spawn) in the environment and the node's ``--ros-args``; prints one line ``PHASES {json}`` on stderr: per
phase end, (wall seconds since T0, process CPU seconds, garbage-collection CPU seconds so far, collections
so far), then stops the node. A checkout without ``switchobs_core.lean_scipy`` or ``early.imported``
(an older one, ``--before``) is started as its own entry point starts it.
"""

from __future__ import annotations

import gc
import json
import os
import sys
import time

T0 = float(os.environ["T0"])
_gc = {"t": 0.0, "t0": 0.0, "n": 0}
marks: dict[str, tuple[float, float, float, int]] = {}


def _collected(phase: str, info: dict) -> None:
    if phase == "start":
        _gc["t0"] = time.process_time()
    else:
        _gc["t"] += time.process_time() - _gc["t0"]
        _gc["n"] += 1


def mark(name: str) -> None:
    marks.setdefault(name, (time.monotonic() - T0, time.process_time(), _gc["t"], _gc["n"]))


def after(owner, attr: str, name: str, before: str | None = None) -> None:
    """Wrap ``owner.attr`` so that its end (and its start, ``before``) is marked."""
    f = getattr(owner, attr)

    def wrapped(*a, **k):
        if before:
            mark(before)
        out = f(*a, **k)
        mark(name)
        return out
    setattr(owner, attr, wrapped)


def main() -> int:
    gc.callbacks.append(_collected)
    mark("interpreter")
    sys.argv[0] = "estimator"
    from switchobs_ros import early
    early.start("estimator")
    mark("participant")
    try:
        from switchobs_core.lean_scipy import import_scipy
        import_scipy()
    except ImportError:         # an older checkout: scipy comes with the node's module
        import scipy.linalg
        import scipy.sparse
        import scipy.special  # noqa: F401
    mark("scipy imported")
    from switchobs_ros import estimator as est
    from switchobs_ros import pipeline as pl
    if hasattr(early, "imported"):
        early.imported()
    mark("node module imported")
    after(est.EstimatorConfig, "from_values", "system built", before="node construction")
    after(pl, "load_or_design_table", "table loaded and checked")
    after(pl, "SwitchedObserver", "observer built")
    after(est.EstimatorMixin, "_ready_log", "ready")
    after(pl.EstimatorPipeline, "on_input", "first input handled", before="first input arrived")
    after(pl.EstimatorPipeline, "on_channel", "first channel handled", before="first channel arrived")
    publish_all = est.EstimatorMixin._publish_all

    def publish(self, outs):
        out = publish_all(self, outs)
        if self.n_published:
            mark("first estimate published")
            print("PHASES " + json.dumps(marks), file=sys.stderr, flush=True)
            raise KeyboardInterrupt     # run_node's stop: exit 0
        return out
    est.EstimatorMixin._publish_all = publish
    return est.main()


if __name__ == "__main__":
    sys.exit(main())
