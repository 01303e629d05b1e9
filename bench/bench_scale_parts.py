#!/usr/bin/env python
"""Where the node pattern's time goes at one size: the parts of ``bench_scale.py --cost``'s node pattern
(Kalman table + the default ellipsoid bound + ``envelope()``) beside the reference Kalman filter.

    OPENBLAS_NUM_THREADS=1 python bench/bench_scale_parts.py --agents 2 8

Seven estimators on the stream of ``bench_scale.py --cost --steady`` (``camera_agents`` M, 50 Hz, after
the table's start-up and one period untimed), interleaved in blocks of 25 samples (the order
rotated), CPU time per sample, medians over the blocks: the table without a bound; with the bound's
step; with the step and ``envelope()`` (the node pattern); the same with the ellipsoid's dense step
(``ErrorEllipsoid.step_dense``) a no-op (the sets stay, everything around them runs); the table
without a bound and ``envelope()`` (the observer's part of a read); the reference filter; and the
node pattern with the compiled kernel (:mod:`switchobs_core.numerics.dense_kernel`) set aside. The
differences give the parts: the dense step, the rest of the bound's step (norms, residual, dispatch),
the observer's ``envelope()`` and the bound's read. A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from bench_scale import ReferenceKF, _cost_setup, _machine, _steady_from


def parts(M: int, samples: int = 1500, block: int = 25) -> dict:
    """Median us per sample of the six estimators (module docstring) for ``camera_agents(M)``."""
    import switchobs_core as so

    system, cycle, table, _ = _cost_setup(M, 1, 1.0)
    warm = _steady_from(system, cycle, table)
    system, cycle, table, stream = _cost_setup(M, warm + samples, 1.0)

    def observer(**kw):
        return so.SwitchedObserver(system, table, "periodic", [cycle], **kw)

    nob, bnd, env, nos, noe = observer(rounding_bound=False), observer(), observer(), observer(), \
        observer(rounding_bound=False)
    noise = so.default_noise(system)
    ref = ReferenceKF(np.asarray(system.A, dtype=float), noise.Q_c, noise.P0, noise.R(1))

    def up(o, k):
        return o.update(stream[k][0], stream[k][1], stream[k][3])

    from switchobs_core.numerics import dense_kernel

    npy = observer()

    def numpy_path(k):      # the node pattern with the compiled kernel set aside (numpy's step and read)
        kept = dense_kernel.STEP, dense_kernel.BETWEEN
        dense_kernel.STEP = dense_kernel.BETWEEN = None
        try:
            up(npy, k)
            npy.envelope()
        finally:
            dense_kernel.STEP, dense_kernel.BETWEEN = kept

    fns = {"table, no bound": lambda k: up(nob, k),
           "table + bound step": lambda k: up(bnd, k),
           "node pattern": lambda k: (up(env, k), env.envelope()),
           "node's step, step_dense a no-op": lambda k: up(nos, k),
           "table, no bound + envelope()": lambda k: (up(noe, k), noe.envelope()),
           "reference": lambda k: ref.update(stream[k][0], stream[k][2], stream[k][3]),
           "node pattern, numpy": numpy_path}
    for k in range(warm):
        for f in fns.values():
            f(k)
    nos.rounding.ell.step_dense = lambda *a: None     # the sets stay as they are (timing only)
    names = list(fns)
    t: dict = {k: [] for k in names}
    for b, lo in enumerate(range(warm, warm + samples - block + 1, block)):
        for name in names[b % len(names):] + names[:b % len(names)]:
            c = time.process_time_ns()
            for k in range(lo, lo + block):
                fns[name](k)
            t[name].append((time.process_time_ns() - c) / block / 1e3)
    med = {k: float(np.median(v[2:])) for k, v in t.items()}
    med["n"] = system.n
    med["kernel"] = dense_kernel.available()
    return med


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[2, 8])
    a = ap.parse_args(argv)
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    load0 = os.getloadavg()[0]
    rows = [parts(M) for M in a.agents]
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_scale_parts.py --agents "
          f"{' '.join(map(str, a.agents))}` (load {load0:.1f} before, {os.getloadavg()[0]:.1f} after; {_machine()})\n")
    print("| us per sample, median | " + " | ".join(f"n = {r['n']}" for r in rows) + " |")
    print("|---|" + "---|" * len(rows))

    def row(label, f, fmt=".1f"):
        print(f"| {label} | " + " | ".join(f"{f(r):{fmt}}" for r in rows) + " |")
    row("the table's estimate (no bound)", lambda r: r["table, no bound"])
    row("the ellipsoid's dense step (`step_dense`)",
        lambda r: r["table + bound step"] - r["node's step, step_dense a no-op"])
    row("the rest of the bound's step (norms, residual, dispatch)",
        lambda r: r["node's step, step_dense a no-op"] - r["table, no bound"])
    row("the observer's `envelope()` around the read",
        lambda r: r["table, no bound + envelope()"] - r["table, no bound"])
    row("the bound's read", lambda r: r["node pattern"] - r["table + bound step"]
        - (r["table, no bound + envelope()"] - r["table, no bound"]))
    row("**the node pattern**", lambda r: r["node pattern"])
    row("the reference Kalman filter", lambda r: r["reference"])
    row("node pattern / reference", lambda r: r["node pattern"] / r["reference"], ".2f")
    if rows and rows[0]["kernel"]:
        row("the node pattern, the compiled kernel set aside (numpy)", lambda r: r["node pattern, numpy"])
        row("node pattern with the kernel / without", lambda r: r["node pattern"] / r["node pattern, numpy"], ".2f")
    return 0


if __name__ == "__main__":
    sys.exit(main())
