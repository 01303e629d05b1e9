#!/usr/bin/env python
"""The core's CPU per sample with the rigorous sets held, in process: an LMI table at 32 agents
(n = 132), a declared ``noise_max``, the innovation test's prior before every sample (not a test;
bench/RESULTS.md).

    python bench/bench_rigorous_step.py [--agents 32] [--rounds 3] [--before /tmp/base] [--warm 200] [--samples 1000]

The system, table and schedule are ``bench_replay.py``'s (``camera_agents(M)`` with every velocity
mode 0.05/s, an LMI table for residences of 1 s, 50 Hz), the samples noise-free outputs of a plant
at rest plus uniform noise of 1 mm within the declared 6 mm. Each child (this checkout, or
``--before``, interleaved over the rounds) runs ``--warm`` samples, then times ``--samples``
samples of ``prior(t)``, ``update`` and ``envelope()`` (``time.process_time``); it prints the CPU
per sample and the last noise bound (the trees' bounds side by side: their difference is the
allowances').
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
import numpy as np
from scipy.linalg import expm
import switchobs_core as so
from switchobs_core.threads import single_threaded_blas
single_threaded_blas()
sysf, table, agents, warm, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
system = so.load_system(sysf)
cyc = so.Cycle([1.0] * agents)
obs = so.SwitchedObserver(system, so.GainTable.load(table, system=system), "periodic", [cyc], e0=1.0,
                          noise_max=[0.006] * agents)
sched = so.PeriodicSchedule(cyc)
rng = np.random.default_rng(2)
F = expm(np.asarray(system.A) / 50.0)
x = np.zeros(system.n)
stream = []
for k in range(warm + count):
    t = k / 50.0
    ch = sched.channel_at(t)
    if k:
        x = F @ x
    stream.append((t, ch, np.asarray(system.C[ch - 1]) @ x + 1e-3 * rng.uniform(-1, 1, 4)))
c0 = 0.0
for k, (t, ch, y) in enumerate(stream):
    if k == warm:
        c0 = time.process_time()
    if k:
        obs.prior(t)
    obs.update(t, ch, y)
    obs.envelope()
c1 = time.process_time()
env = obs.envelope()
print(json.dumps({"ms": (c1 - c0) / count * 1e3, "exact": env.exact_bound, "noise": env.noise_bound}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with, run interleaved")
    ap.add_argument("--warm", type=int, default=200)
    ap.add_argument("--samples", type=int, default=1000)
    a = ap.parse_args()
    sys.path.insert(0, str(REPO))
    from _lmi_child import agents_lmi_table, run_child

    M = a.agents
    sysf, table = agents_lmi_table(M, "switchobs_bench_rigorous_")
    trees = [("this", REPO)] + ([("before", a.before)] if a.before else [])
    got: dict = {name: [] for name, _ in trees}
    for r in range(a.rounds):
        for name, tree in (trees if r % 2 == 0 else trees[::-1]):
            got[name].append(run_child(CHILD, tree, sysf, table, M, a.warm, a.samples))
    print(f"`python bench/bench_rigorous_step.py --agents {M} --rounds {a.rounds} --warm {a.warm} --samples "
          f"{a.samples}{f' --before {a.before}' if a.before else ''}`; load average at the end "
          f"{os.getloadavg()[0]:.1f}.\n")
    print("| tree | CPU per sample (prior, update, envelope), median [min, max] | exact bound | noise bound |")
    print("|---|---|---|---|")
    for name, _ in trees:
        ms = [g["ms"] for g in got[name]]
        last = got[name][-1]
        print(f"| {name} | {statistics.median(ms):.3f} ms [{min(ms):.3f}, {max(ms):.3f}] | {last['exact']!r} | "
              f"{last['noise']!r} |")
    if a.before:
        ratio = statistics.median(t["ms"] / b["ms"] for t, b in zip(got["this"], got["before"]))
        print(f"\nthis / before, per round, median: {ratio:.2f}x")


if __name__ == "__main__":
    main()
