"""The rigorous bound on the audit's systems: units, stiffness, float stamps, channel counts.

``python bench/bench_units.py [--seconds 300]`` prints a markdown report for bench/RESULTS.md:

1. every system of test/core/bounds/_units_audit.py for ``--seconds`` simulated seconds against the
   extended-precision truth: violations, bound finite and ``envelope()`` never raising, the final
   bound / error, the Kalman table's departures, re-locks and share of samples served (second half);
2. a change of the state's units (the estimate started at the truth, ``e0 = 0``): the final
   bound / error ratio in each, and the axes of the final error set mapped back (generalised
   eigenvalues, as square roots);
3. the Kalman table after a first sample 5 s late: the published P against an exact Joseph recursion
   (largest relative error of the trace and of a variance over 40 s);
4. the first visit of a ZOH key at n = 132 (``camera_agents(32)``, 50 Hz): ``scipy.linalg.expm``
   and the proof of its error (median of 20 new keys).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.linalg import eigh

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test" / "core"), str(ROOT / "test" / "core" / "bounds")]

from _units_audit import audit, in_other_units, systems  # noqa: E402

import switchobs_core as so  # noqa: E402
from switchobs_core.numerics.propagation import ZOHCache, van_loan  # noqa: E402
from switchobs_core.numerics.scaling import balance  # noqa: E402


def section_systems(seconds: float) -> None:
    print(f"### 1. {seconds:g} simulated seconds per system against the extended-precision truth\n")
    print("| system | family | samples | violations | bound not finite / raised | final error | final bound "
          "| bound / error | departures / re-locks | served (2nd half) | wall |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, a in systems().items():
        for fam in a.families:
            r = audit(a, fam, seconds, every=1 if seconds <= 60 else 5)
            print(f"| {name} | {fam} | {r['samples']} | {r['violations']} / {r['checks']} | {r['nonfinite']} / "
                  f"{'yes' if r['raised'] else 'no'} | {r['error']:.3g} | {r['bound']:.3g} | {r['ratio']:.3g} | "
                  f"{r['departures']} / {r['relocks']} | {r['served_fraction']:.3f} | {r['seconds']:.1f} s |",
                  flush=True)
    print()


UNITS = {
    "oscillator_si": [np.array([1.0, 1e-3, 1.0, 1.0]), np.array([1e3, 1e-3, 1e2, 10.0]),
                      np.array([1e-3, 1.0, 1e2, 1e3])],
    "wide_units_2": [np.array([1e2, 1.0, 1.0, 1e-2]), np.array([1e-2, 1.0, 1.0, 1e2])],
}


def section_units() -> None:
    print("### 2. A change of the state's units (5 s, estimate started at the truth, e0 = 0)\n")
    print("| system | units T (state i in units T_i times smaller) | bound / error | ratio to the first units "
          "| axes of the error set, mapped back: min - max |")
    print("|---|---|---|---|---|")
    for name, Ts in UNITS.items():
        a = systems()[name]
        rb = audit(a, "kalman", 5.0, exact_start=True)
        print(f"| {name} | 1 | {rb['ratio']:.3g} | 1 | 1 |")
        for T in Ts:
            r = audit(in_other_units(a, T), "kalman", 5.0, exact_start=True)
            w = np.sqrt(eigh(r["S"], rb["S"] * np.outer(T, T), eigvals_only=True))
            print(f"| {name} | {[float(v) for v in T]} | {r['ratio']:.3g} | {r['ratio'] / rb['ratio']:.3g} | "
                  f"{w.min():.3g} - {w.max():.3g} |")
    print()


def section_late_start() -> None:
    print("### 3. Kalman table, first sample 5 s after t0 (paper system, 50 Hz, 40 s)\n")
    paper = so.paper_system()
    cyc = so.Cycle.from_ts(2.0, 0.6)
    table = so.kalman_table(paper, [so.design_kalman(paper, cyc, 50.0)])
    noise = table.kalman_design([cyc], paper).noise
    obs = so.SwitchedObserver(paper, table, "periodic", [cyc], t0=0.0, rounding_bound=False)
    sch = so.PeriodicSchedule(cyc, t0=5.0)
    P, tp, wt, wv, served, N = noise.P0.copy(), 0.0, 0.0, 0.0, 0, 2000
    for k in range(N):
        t = 5.0 + k / 50.0
        ch = sch.channel_at(t)
        F, Qd = van_loan(paper.A, noise.Q_c, t - tp)
        tp = t
        P = F @ P @ F.T + Qd
        H, R = paper.C[ch - 1], noise.R(ch, None)
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        IKH = np.eye(paper.n) - K @ H
        P = IKH @ P @ IKH.T + K @ R @ K.T
        obs.update(t, ch, np.zeros(H.shape[0]))
        Po = obs.P
        wt = max(wt, abs(np.trace(Po) - np.trace(P)) / np.trace(P))
        wv = max(wv, float(np.max(np.abs(np.diag(Po) - np.diag(P)) / np.diag(P))))
        served += k >= N // 2 and obs.gains_source == "table"
    print("| largest trace error | largest variance error | departures / re-locks | served (2nd half) |")
    print("|---|---|---|---|")
    print(f"| {wt:.2%} | {wv:.2%} | {obs.kalman_departures} / {obs.kalman_relocks} | {served / (N - N // 2):.3f} |\n")


def section_first_visit() -> None:
    print("### 4. First visit of a ZOH key at n = 132 (camera_agents(32), a new step each)\n")
    system = so.camera_agents(32)
    A, B = np.asarray(system.A), np.asarray(system.B)
    d = balance(A, np.vstack(system.C))
    times = []
    for k in range(20):
        cache = ZOHCache(scale=d)
        cache.register("open", A, None, B)
        dt = 0.02 + 1e-4 * k          # on the composition grid: an exact step
        t = time.perf_counter()
        cache.step("open", dt)
        times.append(time.perf_counter() - t)
    print(f"median {statistics.median(times) * 1e3:.1f} ms, max {max(times) * 1e3:.1f} ms over 20 keys "
          "(expm of the 264 x 264 ZOH pair and its proof)\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=300.0)
    args = ap.parse_args()
    print(f"## The rigorous bound across units (bench/bench_units.py --seconds {args.seconds:g})\n")
    section_first_visit()
    section_late_start()
    section_units()
    section_systems(args.seconds)


if __name__ == "__main__":
    main()
