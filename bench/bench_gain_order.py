#!/usr/bin/env python
"""What the Kalman design's gains in C order cost: the copy of every designed gain against the design.

    python bench/bench_gain_order.py                  # M = 2, 10, 32
    python bench/bench_gain_order.py --agents 2 10    # a subset

``design_kalman`` stores each phase's gain ``K`` in C order, as a table loaded from its file holds it
(the solver gives ``K`` as a solve's transpose, in Fortran order; the bound sums ``||D^-1 K||_F`` in
memory order, so a designed table and the same table loaded would publish bounds an ulp apart). Per
``camera_agents(M)`` (every h_i = 1 s, 50 Hz, the design's memory budget lifted at M = 32): the
design's CPU time (one run), then in interleaved rounds the CPU time of ``np.ascontiguousarray`` over
Fortran-ordered copies of all its gains (what the design adds) and of ``np.asarray`` over them (the
design without the copy): medians over the rounds. Loading and the observer are untouched (a loaded
table's gains are in C order already)."""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scale import _lift_design_budget, _machine


def _one(M: int, rounds: int) -> dict:
    import switchobs_core as so

    system, cycle = so.camera_agents(M), so.Cycle([1.0] * M)
    _lift_design_budget()
    c0 = time.process_time()
    design = so.design_kalman(system, cycle, 50.0)
    cpu = time.process_time() - c0
    gains = [np.asfortranarray(p.K) for p in design.startup + design.periodic]
    times: dict[str, list[float]] = {"this": [], "before": []}
    for r in range(rounds):
        for name, f in ((("this", np.ascontiguousarray), ("before", np.asarray))[:: 1 if r % 2 else -1]):
            c0 = time.perf_counter()
            for K in gains:
                f(K)
            times[name].append(time.perf_counter() - c0)
    return {"M": M, "n": system.n, "phases": len(gains), "design": cpu,
            **{k: statistics.median(v) for k, v in times.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[2, 10, 32])
    ap.add_argument("--rounds", type=int, default=21)
    args = ap.parse_args(argv)
    print(_machine())
    print("| M | n | phases | design CPU (s) | gains in C order (ms) | before (ms) | added / design |")
    print("|---|---|---|---|---|---|---|")
    for M in args.agents:
        r = _one(M, args.rounds)
        added = r["this"] - r["before"]
        print(f"| {r['M']} | {r['n']} | {r['phases']} | {r['design']:.2f} | {1e3 * r['this']:.2f} | "
              f"{1e3 * r['before']:.2f} | {added / r['design']:.1e} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
