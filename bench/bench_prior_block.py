#!/usr/bin/env python
"""The bias test's prior covariance at 32 agents, in process: the LMI family with a noise model,
``prior_covariance(t, cols)`` on each sample's columns before every ``update`` (what
``runtime/recovery.py``'s bias test reads), with ``P`` read after every sample (a published
estimate carries it) or never (not a test; bench/RESULTS.md).

    python bench/bench_prior_block.py [--agents 32] [--rounds 3] [--before /tmp/base] [--warm 1700] [--samples 1600]

The system and table are ``bench_replay.py``'s (``camera_agents(M)``, every velocity mode 0.05/s,
an LMI table for residences of 1 s, 50 Hz), the samples noise-free outputs of a plant at rest plus
1 mm of uniform noise. ``--warm`` samples first (by default more than a cycle: every channel's
steps and powers are cached, as in a long replay), then ``--samples`` timed
(``time.process_time``): the CPU per sample of the whole loop and of ``prior_covariance`` alone.
Each child (this checkout, or ``--before``, interleaved over the rounds, both read modes) prints
them and the trace of the last ``P`` (the trees' covariances side by side).
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
from switchobs_core.model.noise import default_noise
from switchobs_core.runtime.consistency import seen_columns
from switchobs_core.threads import single_threaded_blas
single_threaded_blas()
sysf, table = sys.argv[1], sys.argv[2]
agents, warm, count, read = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6] == "1"
system = so.load_system(sysf)
cyc = so.Cycle([1.0] * agents)
obs = so.SwitchedObserver(system, so.GainTable.load(table, system=system), "periodic", [cyc], e0=1.0,
                          noise=default_noise(system))
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
cols = {c: seen_columns(np.asarray(system.C[c - 1])) for c in range(1, agents + 1)}
c0 = tp = 0.0
for k, (t, ch, y) in enumerate(stream):
    if k == warm:
        c0, tp = time.process_time(), 0.0
    if k:
        a = time.process_time()
        obs.prior_covariance(t, cols[ch])
        tp += time.process_time() - a
    obs.update(t, ch, y)
    if read:
        obs.P
c1 = time.process_time()
print(json.dumps({"ms": (c1 - c0) / count * 1e3, "prior_ms": tp / count * 1e3, "trace": float(np.trace(obs.P))}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with, run interleaved")
    ap.add_argument("--warm", type=int, default=1700)
    ap.add_argument("--samples", type=int, default=1600)
    a = ap.parse_args()
    sys.path.insert(0, str(REPO))
    from _lmi_child import agents_lmi_table, run_child

    M = a.agents
    sysf, table = agents_lmi_table(M, "switchobs_bench_prior_block_")
    trees = [("this", REPO)] + ([("before", a.before)] if a.before else [])
    got: dict = {(name, read): [] for name, _ in trees for read in ("1", "0")}
    for r in range(a.rounds):
        for name, tree in (trees if r % 2 == 0 else trees[::-1]):
            for read in ("1", "0"):
                got[(name, read)].append(run_child(CHILD, tree, sysf, table, M, a.warm, a.samples, read))
    print(f"`python bench/bench_prior_block.py --agents {M} --rounds {a.rounds} --warm {a.warm} --samples "
          f"{a.samples}{f' --before {a.before}' if a.before else ''}`; load average at the end "
          f"{os.getloadavg()[0]:.1f}.\n")
    print("| tree | P read | CPU per sample, median [min, max] | of it prior_covariance | trace of the last P |")
    print("|---|---|---|---|---|")
    for read in ("1", "0"):
        for name, _ in trees:
            g = got[(name, read)]
            ms, pm = [x["ms"] for x in g], [x["prior_ms"] for x in g]
            print(f"| {name} | {'every sample' if read == '1' else 'never'} | {statistics.median(ms):.3f} ms "
                  f"[{min(ms):.3f}, {max(ms):.3f}] | {statistics.median(pm):.3f} ms | {g[-1]['trace']!r} |")
    if a.before:
        for read in ("1", "0"):
            ratio = statistics.median(t["ms"] / b["ms"] for t, b in zip(got[("this", read)], got[("before", read)]))
            print(f"\nthis / before, P read {'every sample' if read == '1' else 'never'}, per round, median: "
                  f"{ratio:.2f}x")


if __name__ == "__main__":
    main()
