#!/usr/bin/env python
"""Accuracy of a Kalman table over missing samples at 32 agents (n = 132), in process (not a test;
bench/RESULTS.md).

    python bench/bench_gaps.py [--table /tmp/boot/k32v4.npz] [--drop 0.1] [--seconds 104]

A plant (``camera_agents`` with M agents, exact process noise of the table's noise model, every
``h_i = 1 s``, 50 Hz, measurement noise of the model) feeds three observers of the same table with
the same draws: every sample (``all``), a fraction ``--drop`` of the samples missing with the
default ``missing="table"`` (the table's grid kept, the covariance's deviation in low rank,
:mod:`switchobs_core.runtime.families.gaps`), and the same samples missing with
``missing="online"`` (a departure: the Riccati recursion online until it re-locks). Reported per
observer: the RMS error ``sqrt(mean ||x_hat - x||^2)`` over the run and over the steady window
(after the table's start-up), the average NEES ``e' P^-1 e / n`` there (1 for a consistent
filter), the samples answered online, the CPU per answer, and the largest difference of the
``table`` and ``online`` estimates relative to the error's RMS. A tree without the ``missing``
option (an older checkout, through ``PYTHONPATH``) runs what it has.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from scipy.linalg import expm


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz")
    ap.add_argument("--drop", type=float, default=0.1)
    ap.add_argument("--seconds", type=float, default=104.0)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    import switchobs_core as so
    from switchobs_core.model.scenarios import camera_agents
    from switchobs_core.model.schedule import Cycle, PeriodicSchedule
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    system = camera_agents(a.agents)
    table = so.GainTable.load(a.table, system=system)
    cyc = Cycle((1.0,) * a.agents)
    rate, n = 50.0, system.n
    modes = {"all": None, "table": "table", "online": "online"}
    obs = {}
    for name, how in modes.items():
        o = so.SwitchedObserver(system, table, "periodic", [cyc], x0=np.zeros(n), e0=1e3)
        if how is not None and hasattr(o.gains, "missing"):
            o.gains.missing = how
        elif how == "online" and not hasattr(o.gains, "missing"):
            continue                    # an older tree: its "table" run is the departure path
        obs[name] = o
    kd = obs["all"].kalman
    noise = kd.noise
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -system.A, noise.Q_c, system.A.T
    E = expm(M / rate)
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    LQ = np.linalg.cholesky(0.5 * (Qd + Qd.T) + 1e-300 * np.eye(n))
    rng = np.random.default_rng(a.seed)
    K = int(a.seconds * rate)
    drop = rng.random(K) < a.drop
    drop[:int(rate)] = False
    x = np.linalg.cholesky(noise.P0) @ rng.standard_normal(n)
    sched = PeriodicSchedule(cyc)
    k_steady = len(kd.startup) + int(rate)
    sq = {m: [] for m in obs}
    nees = {m: [] for m in obs}
    online = dict.fromkeys(obs, 0)
    cpu = dict.fromkeys(obs, 0.0)
    answers = dict.fromkeys(obs, 0)
    worst = 0.0
    for k in range(K):
        t = k / rate
        if k:
            x = F @ x + LQ @ rng.standard_normal(n)
        c = sched.channel_at(t)
        R = noise.R(c)
        y = system.C[c - 1] @ x + np.linalg.cholesky(R) @ rng.standard_normal(R.shape[0])
        est = {}
        for m, o in obs.items():
            if drop[k] and m != "all":
                continue
            c0 = time.process_time()
            xh = o.update(t, c, y)
            cpu[m] += time.process_time() - c0
            answers[m] += 1
            online[m] += o.gains_source == "online"
            e = xh - x
            est[m] = xh.copy()
            if k >= k_steady:
                sq[m].append(float(e @ e))
                if k % 25 == 0:
                    nees[m].append(float(e @ np.linalg.solve(o.P, e)) / n)
        if "table" in est and "online" in est and k >= k_steady and sq["all"]:
            worst = max(worst, float(np.linalg.norm(est["table"] - est["online"])))
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_gaps.py --agents {a.agents} --table {a.table} "
          f"--drop {a.drop:g} --seconds {a.seconds:g} --seed {a.seed}` (n = {n}; "
          f"PYTHONPATH {os.environ.get('PYTHONPATH', '')}; load {os.getloadavg()[0]:.1f} after)\n")
    print(f"Steady window: {k_steady / rate:.1f}-{a.seconds:g} s; {int(drop.sum())} of {K} samples missing\n")
    print("| observer | answers | served online | RMS error (steady) | ratio to every sample | mean NEES / n | "
          "CPU per answer, ms |")
    print("|---|---|---|---|---|---|---|")
    base = np.sqrt(np.mean(sq["all"]))
    for m in obs:
        rms = np.sqrt(np.mean(sq[m]))
        print(f"| {m} | {answers[m]} | {online[m]} | {rms:.4g} | {rms / base:.4f} | {np.mean(nees[m]):.3f} "
              f"| {cpu[m] / answers[m] * 1e3:.3f} |")
    if "online" in obs:
        print(f"\nlargest |x_table - x_online| in the steady window: {worst:.3g} ({worst / base:.2g} of the RMS error)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
