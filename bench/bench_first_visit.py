#!/usr/bin/env python
"""No stall at n = 132: the first visit of a channel, and the extended-precision exponential.

    python bench/bench_first_visit.py [--rounds 3] [--seconds 2]

On 32 agents whose velocity modes are all 0.05/s (``camera_agents(32, D_agents=[(0, 0.05)] * 32)``,
n = 132, every h_i = 1 s, 50 Hz; the well-posed model of bench/bench_precision.py), CPU time, medians
over ``--rounds`` rounds, ours and the alternative interleaved in each round:

1. ``expm_extended`` (:mod:`switchobs_core.numerics.extended`: products by error-free splitting in
   double-precision BLAS) against the same scaling and squaring with numpy's ``longdouble`` products
   (the implementation it replaces, reproduced here), for a 50 Hz step, a jittered one and a 1 s
   residence: time, ratio and the largest difference relative to the largest entry;
2. the extended-precision plant of ``simulate`` (``Plant(extended=True)``, one exponential per new
   step) over ``--seconds`` simulated seconds with the ``kalman`` table, with each exponential;
3. the observer's first period, in which every channel and sample phase is visited for the first
   time (``update`` + ``envelope()`` per sample, a fresh observer per round, the ``kalman`` and
   ``lmi`` tables): the median and the largest sample against those of the second period.

A script, not a test: nothing is asserted. Goal: a first visit <= 50 ms.
"""

from __future__ import annotations

import argparse
import math
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
from switchobs_core.numerics.extended import expm_extended  # noqa: E402
from switchobs_core.sim import plant as plant_module  # noqa: E402
from switchobs_core.sim.simulate import simulate  # noqa: E402

M = 32
RATE = 50.0
LD = np.longdouble


def expm_longdouble(A: np.ndarray, dt: float) -> np.ndarray:
    """The alternative: scaling and squaring of a Taylor series with numpy's ``longdouble`` products
    (a plain loop, no BLAS)."""
    X = np.asarray(A, dtype=LD) * LD(dt)
    nrm = float(np.abs(X).sum(axis=0).max()) if X.size else 0.0
    s = max(0, int(math.ceil(math.log2(nrm))) + 1) if nrm > 0.5 else 0
    X = X / LD(2.0**s)
    E = np.eye(X.shape[0], dtype=LD)
    T = E.copy()
    tiny = float(np.finfo(LD).eps) / 16
    for k in range(1, 40):
        T = T @ X / LD(k)
        E = E + T
        if float(np.abs(T).max()) <= tiny * float(np.abs(E).max()):
            break
    for _ in range(s):
        E = E @ E
    return E


def cpu(f) -> tuple[float, object]:
    c = time.process_time()
    out = f()
    return time.process_time() - c, out


def section_expm(system, rounds: int) -> None:
    print("### 1. `expm_extended` at n = 132: BLAS splitting against numpy longdouble products\n")
    print("| step | ours (median CPU) | longdouble products | ratio | largest difference / largest entry |")
    print("|---|---|---|---|---|")
    A = np.asarray(system.A)
    for label, dt in (("50 Hz (0.02 s)", 0.02), ("jittered (0.0213 s)", 0.0213), ("a residence (1 s)", 1.0)):
        ours, alt, diff = [], [], 0.0
        for _ in range(rounds):
            t1, E1 = cpu(lambda dt=dt: expm_extended(A, dt))
            t2, E2 = cpu(lambda dt=dt: expm_longdouble(A, dt))
            ours.append(t1)
            alt.append(t2)
            diff = max(diff, float(np.abs(E1 - E2).max() / np.abs(E2).max()))
        mo, ma = statistics.median(ours), statistics.median(alt)
        print(f"| {label} | {mo * 1e3:.1f} ms | {ma * 1e3:.1f} ms | {mo / ma:.2f}x | {diff:.1e} |")
    print()


def section_simulate(system, cycle, table, rounds: int, seconds: float) -> None:
    print(f"### 2. `simulate` with the extended-precision plant, {seconds:g} s at 50 Hz (kalman table)\n")
    x0 = np.random.default_rng(1).uniform(-5, 5, system.n)
    sched = so.PeriodicSchedule(cycle)
    stamps = np.arange(int(seconds * RATE) + 1) / RATE         # simulate's stamps (t0 = 0)
    keys = len({float(b) - float(a) for a, b in zip(stamps[:-1], stamps[1:])})

    def run():
        return simulate(system, table, sched, x0, np.zeros(system.n), seconds, rate=RATE)

    ours, alt = [], []
    for _ in range(rounds):
        plant_module.expm_extended = expm_extended
        ours.append(cpu(run)[0])
        plant_module.expm_extended = expm_longdouble
        alt.append(cpu(run)[0])
    plant_module.expm_extended = expm_extended
    samples = int(seconds * RATE) + 1
    mo, ma = statistics.median(ours), statistics.median(alt)
    print("| plant's exponential | run (median CPU) | per sample | ratio |")
    print("|---|---|---|---|")
    print(f"| ours | {mo:.2f} s | {mo / samples * 1e3:.1f} ms | {mo / ma:.2f}x |")
    print(f"| longdouble products | {ma:.2f} s | {ma / samples * 1e3:.1f} ms | 1 |")
    print(f"\n({samples} samples; the float stamps k / 50 give {keys} distinct steps, each a new "
          "exponential of the plant.)\n")


def section_observer(system, cycle, tables: dict, rounds: int) -> None:
    print("### 3. The observer's first period (first visit of every channel) against its second\n")
    print("| table | first period: median | largest | second period: median | largest | goal <= 50 ms |")
    print("|---|---|---|---|---|---|")
    sched = so.PeriodicSchedule(cycle)
    per = int(round(sum(cycle.h) * RATE))
    rng = np.random.default_rng(0)
    x = rng.uniform(-5, 5, system.n)
    stream = []
    for k in range(2 * per):
        t = k / RATE
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        stream.append((t, ch, H @ x + rng.normal(scale=1e-3, size=H.shape[0])))
    for name, table in tables.items():
        first, second = [], []
        for _ in range(rounds):
            obs = so.SwitchedObserver(system, table, "periodic", [cycle])
            for k, (t, ch, y) in enumerate(stream):
                c = time.process_time()
                obs.update(t, ch, y)
                obs.envelope()
                (first if k < per else second).append(time.process_time() - c)
        big = max(first)
        print(f"| {name} | {statistics.median(first) * 1e3:.2f} ms | {big * 1e3:.1f} ms | "
              f"{statistics.median(second) * 1e3:.2f} ms | {max(second) * 1e3:.1f} ms | "
              f"{'met' if big <= 0.05 else '**not met**'} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=2.0)
    a = ap.parse_args()
    from bench_scale import _lift_design_budget

    system = so.camera_agents(M, D_agents=[(0.0, 0.05)] * M)
    cycle = so.Cycle([1.0] * M)
    print(f"## No stall at n = {system.n} (bench/bench_first_visit.py --rounds {a.rounds} --seconds {a.seconds:g})\n")
    section_expm(system, a.rounds)
    _lift_design_budget()
    kal = so.kalman_table(system, [so.design_kalman(system, cycle, RATE)])
    section_simulate(system, cycle, kal, a.rounds, a.seconds)
    lmi = so.design_table(system, [cycle], progress=False)
    section_observer(system, cycle, {"kalman": kal, "lmi": lmi}, a.rounds)


if __name__ == "__main__":
    main()
