"""Re-certification on a body that manoeuvres without a declared disturbance.

The three-channel camera model (``camera_agents(3)``, one second per channel), Kalman table for
1 mm noise, Gaussian noise of 1 mm clipped to ``noise.max`` = 3 mm, ``e0`` 0.5, 50 Hz; agent 1
accelerates along x at ``a`` m/s^2 from 5 s to the end of a 60 s run; no disturbance declared. The
node's loop in process (:func:`switchobs_core.sim.faults.run_with_faults`: the consistency test, the
bias test, the re-certification). For each acceleration and seed: false samples before and after
the first withdrawal, the re-certifications, with the window's row-by-row test
(:func:`switchobs_core.runtime.recertify.chebyshev`) and without it (the norm over the window
alone) side by side in one run; the CPU time per sample of both.

``python bench/bench_manoeuvre_recovery.py [--seeds 5] [--seconds 60]``; results in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bench_design import machine_info  # noqa: E402

import switchobs_core as so  # noqa: E402
from switchobs_core.model.scenarios import camera_agents, load_disturbance, load_noise  # noqa: E402
from switchobs_core.model.schedule import Cycle, PeriodicSchedule  # noqa: E402
from switchobs_core.runtime import recertify  # noqa: E402
from switchobs_core.sim.disturbed import step_input  # noqa: E402
from switchobs_core.sim.faults import run_with_faults  # noqa: E402
from switchobs_core.threads import single_threaded_blas  # noqa: E402

SIGMA = 1e-3
ONSET = 5.0


def one(setup, a: float, seed: int, seconds: float, rows: bool) -> dict:
    sys_, noise, table, x0, B_w, cyc = setup
    run = lambda: run_with_faults(sys_, table, PeriodicSchedule(cyc), x0, x0, seconds, rate=50.0,
                                  noise_std=SIGMA, noise_max=3 * SIGMA, e0=0.5, seed=seed, noise=noise, B_w=B_w,
                                  w=step_input(B_w.shape[1], 2, a, ONSET))
    t0 = time.process_time()
    if rows:
        r = run()
    else:
        with mock.patch.object(recertify, "chebyshev", lambda R, r, tol: 0.0):
            r = run()
    cpu = (time.process_time() - t0) / r.t.size
    false = r.valid & (r.error > r.bound)
    tw = r.withdrawals[0][0] if r.withdrawals else math.inf
    return {"before": int(np.sum(false & (r.t < tw))), "after": int(np.sum(false & (r.t >= tw))),
            "withdrawn": tw - ONSET, "recert": len(r.recertified), "cpu": cpu,
            "valid": r.valid_fraction(ONSET)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args(argv)
    single_threaded_blas()
    sys_ = camera_agents(3)
    cyc = Cycle((1.0, 1.0, 1.0))
    noise = load_noise("camera_agents", sys_, meas_std=SIGMA)
    table = so.kalman_table(sys_, [so.design_kalman(sys_, [cyc], 50.0, noise=noise)])
    x0 = np.zeros(sys_.n)
    x0[4:16:4] = (3.0, -2.0, 1.0)
    setup = (sys_, noise, table, x0, load_disturbance("camera_agents", sys_).B_w, cyc)
    print(machine_info())
    print(f"camera_agents(3), Kalman, noise 1 mm clipped to 3 mm, agent 1 at a m/s^2 from {ONSET} s, "
          f"{a.seconds:g} s, {a.seeds} seeds, no disturbance declared\n")
    print("| a (m/s^2) | window test | false before the withdrawal (sum) | false after it (sum) | "
          "withdrawn after the onset (s, max) | re-certifications (sum) | valid after the onset (max) | "
          "CPU per sample (us, median) |")
    print("|---|---|---|---|---|---|---|---|")
    for acc in (0.2, 0.5, 1.0):
        for rows in (True, False):
            res = [one(setup, acc, s, a.seconds, rows) for s in range(a.seeds)]
            print(f"| {acc:g} | {'rows' if rows else 'norm only'} | {sum(r['before'] for r in res)} "
                  f"| {sum(r['after'] for r in res)} | {max(r['withdrawn'] for r in res):.2f} "
                  f"| {sum(r['recert'] for r in res)} | {max(r['valid'] for r in res):.3f} "
                  f"| {statistics.median(r['cpu'] for r in res) * 1e6:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
