#!/usr/bin/env python
"""The LMI family's covariance taken when read: cost per sample by how often ``P`` is read.

    python bench/bench_covariance.py [--agents 2 8 32] [--samples 600] [--rounds 3]

``camera_agents(M)`` with every velocity mode 0.05/s (n = 4 (M + 1)), every h_i = 1 s, 50 Hz, noisy
samples (1 mm) of a plant at rest; an LMI table for that cycle; ``SwitchedObserver`` with the
default noise model (the covariance tracked) and the exact bound, ``update`` + ``envelope()`` per
sample, and ``P`` read at every sample (what the estimator node does when it publishes the
covariance), every 10th sample, or never (once at the end); the same without a covariance; and
the reference Kalman filter of bench/bench_scale.py. CPU time per sample, the samples interleaved
in blocks of 25 across the variants, medians over the blocks of ``--rounds`` rounds. A script,
not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from switchobs_core.threads import single_threaded_blas  # noqa: E402

single_threaded_blas()

import switchobs_core as so  # noqa: E402
from switchobs_core.model.noise import default_noise  # noqa: E402

RATE = 50.0
BLOCK = 25


def bench(M: int, samples: int, rounds: int) -> dict:
    from bench_scale import ReferenceKF

    system = so.camera_agents(M, D_agents=[(0.0, 0.05)] * M)
    cycle = so.Cycle([1.0] * M)
    table = so.design_table(system, [cycle], progress=False)
    noise = default_noise(system)
    sched = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(M)
    x = np.zeros(system.n)
    x[0::4] = rng.uniform(-5, 5, M + 1)
    stream = []
    for k in range(samples):
        t = k / RATE
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        stream.append((t, ch, H, H @ x + rng.normal(scale=1e-3, size=H.shape[0])))
    times: dict = {}
    for _ in range(rounds):
        obs = {"P read at every sample (the node)": (so.SwitchedObserver(system, table, "periodic", [cycle],
                                                                          noise=noise), 1),
               "P read every 10th sample": (so.SwitchedObserver(system, table, "periodic", [cycle], noise=noise), 10),
               "P never read": (so.SwitchedObserver(system, table, "periodic", [cycle], noise=noise), 0),
               "no covariance": (so.SwitchedObserver(system, table, "periodic", [cycle]), 0)}
        ref = ReferenceKF(np.asarray(system.A), noise.Q_c, noise.P0, noise.R(1))

        def run(name, k0, obs=obs, ref=ref):
            if name == "reference Kalman filter":
                for t, _, H, y in stream[k0:k0 + BLOCK]:
                    ref.update(t, H, y)
                return
            o, every = obs[name]
            for k in range(k0, k0 + BLOCK):
                t, ch, _, y = stream[k]
                o.update(t, ch, y)
                o.envelope()
                if every and k % every == 0:
                    o.P  # noqa: B018 - the read is what is measured

        names = [*obs, "reference Kalman filter"]
        for b, k0 in enumerate(range(0, samples - BLOCK + 1, BLOCK)):
            for name in names[b % len(names):] + names[:b % len(names)]:
                c = time.process_time_ns()
                run(name, k0)
                if b >= 2:      # the first blocks: first visits of the ZOH cache
                    times.setdefault(name, []).append((time.process_time_ns() - c) / BLOCK / 1e3)
        obs["P never read"][0].P  # noqa: B018
    return {"n": system.n, "us": {k: statistics.median(v) for k, v in times.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[2, 8, 32])
    ap.add_argument("--samples", type=int, default=600)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    rows = [bench(M, a.samples, a.rounds) for M in a.agents]
    names = list(rows[0]["us"])
    print(f"`python bench/bench_covariance.py --agents {' '.join(map(str, a.agents))} --samples {a.samples} "
          f"--rounds {a.rounds}`\n")
    print("| LMI observer, exact bound, envelope() per sample (us per sample, median) | "
          + " | ".join(f"n = {r['n']}" for r in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for name in names:
        print(f"| {name} | " + " | ".join(f"{r['us'][name]:.1f}" for r in rows) + " |")
    ref = "reference Kalman filter"
    print("| ratio: P read at every sample / reference | "
          + " | ".join(f"{r['us']['P read at every sample (the node)'] / r['us'][ref]:.2f}" for r in rows) + " |")
    print("| ratio: P never read / reference | "
          + " | ".join(f"{r['us']['P never read'] / r['us'][ref]:.2f}" for r in rows) + " |")


if __name__ == "__main__":
    main()
