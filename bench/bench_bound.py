"""Benchmark: the exact bound with rounding over long runs, against an extended-precision truth.

Run: ``.venv/bin/python bench/bench_bound.py MINUTES RATE`` (e.g. ``10 100``). Not a test.

The paper's plant (unstable agents: ||x|| grows to about 160 in 10 minutes) is propagated in
extended precision (``np.longdouble`` exponentials); its outputs, rounded once to double, feed the
observer with the paper's LMI gains and with offline Kalman gains, periodic (2 s, 0.6) and the
nonperiodic sequence. Reported per run: the number of samples at which the computed estimate's
true error exceeds the published ``exact_bound`` (must be 0), how tight the bound stays once the
error sits at the rounding floor (median bound/error over the second half), the final values
and the wall time.
"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import switchobs_core as so
from switchobs_core.numerics.rounding import verify_against_extended
from switchobs_core.threads import single_threaded_blas

sysm = so.load_system("paper")
per = [so.Cycle.from_ts(2, 0.6)]
seq = [so.Cycle.from_ts(4, 0.5), so.Cycle.from_ts(3, 0.6), so.Cycle.from_ts(3, 0.6), so.Cycle.from_ts(2, 0.4)]
single_threaded_blas()
minutes = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
rate = float(sys.argv[2]) if len(sys.argv) > 2 else 100.0
lmi = so.design_table(sysm, cycles=per + seq, delta=0.99, progress=False)


def run(name, table, mode, cycles, sched):
    obs = so.SwitchedObserver(sysm, table, mode, cycles, x0=np.zeros(12), e0=10.0)
    x0 = np.array([0, 0, 0.2, 0.1, 3, 1, -0.1, 0, -2, 2, 0.1, 0], dtype=float)   # ||x_hat0 - x0|| < 10
    t0 = time.time()
    r = verify_against_extended(sysm, obs, sched, rate, minutes * 60, x0)
    q = r["ratios"]
    print(f"| {name} | {minutes:g} min, {rate:g} Hz | {r['violations']} of {r['samples']} | "
          f"{np.median(q[len(q) // 2:]):.3g} | {q.min():.3g} | {r['error']:.3g} | {r['bound']:.3g} | "
          f"{r['norm_x']:.3g} | {time.time() - t0:.1f} s |", flush=True)


print("| run | length | violations | bound/error (median, 2nd half) | min | final error | final bound | "
      "final ||x|| | wall |")
print("|---|---|---|---|---|---|---|---|---|")
run("lmi periodic", lmi, "periodic", per, so.PeriodicSchedule(per[0]))
run("lmi sequence", lmi, "sequence", seq, so.SequenceSchedule(seq))
run("kalman periodic", so.kalman_table(sysm, [so.design_kalman(sysm, per, rate)]), "periodic", per,
    so.PeriodicSchedule(per[0]))
run("kalman sequence", so.kalman_table(sysm, [so.design_kalman(sysm, seq, rate)]), "sequence", seq,
    so.SequenceSchedule(seq))
