"""Recovery of the guarantee (switchobs_core.runtime.recovery): faults, re-certification, no e0.

The paper's three planar bodies, 50 Hz, the periodic (2 s, 0.6) schedule, Kalman gains designed for
1 cm noise, Gaussian noise of 1 cm clipped to ``noise.max`` = 3 cm, each case over several seeds,
both in process (:func:`switchobs_core.sim.faults.run_with_faults`) and through ``switchobs_bag
estimate`` on a generated recording (``switchobs_bag generate --bias``):

* ``bias``: 5 cm added to the target poses for 2 s (from 8.5 s): false samples (must be 0), the
  detection delay, the time from the fault's end to a bound again, the valid fraction from two
  cycles after the fault;
* ``fault``: the same with 1 m (a gross sensor fault) for 2 s;
* ``e0=-1``: no initial bound, the initial estimate metres off: false samples, the time to the
  first bound, the valid fraction after three cycles;
* ``holds``: no fault, ``e0`` given: false samples, valid fraction, median bound / median error;
* the CUSUM's delay for a bias of k sigma (unit-variance draws) beside its stated approximation;
* the cost: CPU time per sample of the in-process run with the recovery on and off, side by side,
  interleaved rounds, medians.

``python bench/bench_recovery.py [--seeds 5] [--rounds 3]``; results in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bench_design import machine_info  # noqa: E402

from switchobs_core.design.kalman import design_kalman  # noqa: E402
from switchobs_core.model.noise import NoiseModel  # noqa: E402
from switchobs_core.model.scenarios import paper_system  # noqa: E402
from switchobs_core.model.schedule import Cycle, PeriodicSchedule  # noqa: E402
from switchobs_core.runtime.bias import BiasDetector, cusum_delay  # noqa: E402
from switchobs_core.sim.faults import Fault, run_with_faults  # noqa: E402
from switchobs_core.table.gains import kalman_table  # noqa: E402
from switchobs_core.threads import single_threaded_blas  # noqa: E402

CYC = Cycle.from_ts(2.0, 0.6)
X0 = np.array([0, 0, 0.1, 0, 1, 2, 0.2, -0.1, -1, 3, 0, 0.2], float)       # camera_sim's scene
OFF = np.array([3, -2, 0.5, 0.5, 2, 2, 0, 0, -3, 1, 0.3, 0], float)        # metres off
F0, F1 = 8.5, 10.5
T_END = 20.0
PARAMS = {"gain_family": "kalman", "rate": 50.0, "noise.measurement_std": 0.01, "noise.process_std": 0.01,
          "noise.max": 0.03}


def _first(a: np.ndarray) -> float:
    return float(a[0]) if a.size else float("inf")


def _stats(t: np.ndarray, err: np.ndarray, bound: np.ndarray, case: str) -> dict:
    """The figures of one run from its per-sample time, error and published bound (-1: none)."""
    valid = bound >= 0
    out = {"false": int(np.sum(valid & (err > bound)))}
    if case in ("bias", "fault"):
        out["detect"] = _first(t[(t >= F0) & ~valid]) - F0
        out["back"] = _first(t[(t >= F1) & valid]) - F1
        out["valid"] = float(valid[t >= F1 + 2 * CYC.tau].mean())
    elif case == "e0=-1":
        out["first"] = _first(t[valid]) - t[0]
        out["valid"] = float(valid[t >= t[0] + 3 * CYC.tau].mean())
    else:
        out["valid"] = float(valid.mean())
        out["ratio"] = float(np.median(bound[valid]) / np.median(err))
    return out


def _in_process(table, case: str, seed: int) -> dict:
    system, sched = paper_system(), PeriodicSchedule(CYC)
    faults = {"bias": [Fault(F0, F1, (2, 3), 0.05)], "fault": [Fault(F0, F1, (2, 3), 1.0)]}.get(case, [])
    xh, e0 = (X0 + OFF, None) if case == "e0=-1" else (X0 + 0.05, 1.0)
    run = run_with_faults(system, table, sched, X0, xh, T_END, rate=50.0, noise_std=0.01, noise_max=0.03, e0=e0,
                          faults=faults, seed=seed)
    return _stats(run.t, run.error, run.bound, case)


def _bag(tmp: Path, case: str, seed: int) -> dict:
    from switchobs_ros.bag.estimate import estimate, estimator_params
    from switchobs_ros.bag.generate import GenerateConfig, generate
    from switchobs_ros.bag.report import load_report

    bias = {"bias": (F0, F1, 0.05), "fault": (F0, F1, 1.0)}.get(case, ())
    bag = tmp / f"{case}-{seed}"
    generate(bag, GenerateConfig(rate=50.0, duration=T_END, noise_std=0.01, noise_max=0.03, extended=True,
                                 seed=seed, bias=bias), "mcap")
    over = {**PARAMS, "gain_table_cache_dir": str(tmp / "cache"), "e0": 10.0}
    if case == "e0=-1":
        over.update({"e0": -1.0, "initial_estimate": list(X0 + OFF)})
    estimate(bag, estimator_params(overrides=over), out=tmp / f"{bag.name}-est")
    (p,) = load_report(tmp / f"{bag.name}-est", "/estimator").passes
    return _stats(np.asarray(p.t), np.asarray(p.err), np.asarray(p.noise), case)


def _cusum(b: float, runs: int = 400) -> float:
    delays = []
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        d = BiasDetector((1,))
        k = 1
        while d.update(1, None, rng.standard_normal(1) + b) is None:
            k += 1
        delays.append(k)
    return float(np.mean(delays))


def _cost(table, rounds: int, faults: list) -> dict:
    """CPU s per sample of the in-process run, recovery on / off (interleaved rounds, medians)."""
    system, sched = paper_system(), PeriodicSchedule(CYC)
    per = {"on": [], "off": []}
    for _ in range(rounds):
        for name, opts in (("on", {}), ("off", {"recertify": False, "bias": False, "reinit": False})):
            t = time.process_time()
            run = run_with_faults(system, table, sched, X0, X0 + 0.05, T_END, rate=50.0, noise_std=0.01,
                                  noise_max=0.03, e0=1.0, faults=faults, recovery=opts)
            per[name].append((time.process_time() - t) / run.t.size)
    return {k: statistics.median(v) for k, v in per.items()}


def _fmt(rows: list[dict], key: str, how=max) -> str:
    vals = [r[key] for r in rows]
    return f"{how(vals):.3g}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-bag", action="store_true", help="in process only")
    a = ap.parse_args(argv)
    single_threaded_blas()
    system = paper_system()
    nm = NoiseModel(meas_std=((0.01,) * 4,) * 2, Q_c=1e-4 * np.eye(12), P0=100 * np.eye(12))
    table = kalman_table(system, [design_kalman(system, CYC, 50.0, nm)])
    print(machine_info())
    print(f"paper system, 50 Hz, (2 s, 0.6), noise 1 cm clipped to 3 cm, {a.seeds} seeds; faults {F0}-{F1} s\n")
    print("| case | path | false (sum) | detection delay (s, max) | fault end -> bound (s, max) | first bound (s, max) "
          "| valid fraction (min) | median bound / median error |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for case in ("holds", "bias", "fault", "e0=-1"):
            for path in ("in process", "switchobs_bag estimate"):
                if path != "in process" and a.no_bag:
                    continue
                rows = [(_in_process(table, case, s) if path == "in process" else _bag(Path(d), case, s))
                        for s in range(a.seeds)]
                print(f"| {case} | {path} | {sum(r['false'] for r in rows)} "
                      f"| {_fmt(rows, 'detect') if 'detect' in rows[0] else ''} "
                      f"| {_fmt(rows, 'back') if 'back' in rows[0] else ''} "
                      f"| {_fmt(rows, 'first') if 'first' in rows[0] else ''} "
                      f"| {_fmt(rows, 'valid', min)} "
                      f"| {_fmt(rows, 'ratio', statistics.median) if 'ratio' in rows[0] else ''} |")
    print("\n| bias (sigma) | CUSUM mean delay (samples, 400 runs) | stated (h + 1.166) / (b - k) |")
    print("|---|---|---|")
    for b in (3.0, 4.0, 5.0):
        print(f"| {b:g} | {_cusum(b):.2f} | {cusum_delay(b):.2f} |")
    print()
    for what, faults in (("no fault (the bias test only)", []), ("gross fault (withdrawn 2 s: the window too)",
                                                                  [Fault(F0, F1, (2, 3), 1.0)])):
        c = _cost(table, a.rounds, faults)
        print(f"cost per sample of the in-process run, {what}, median of {a.rounds}: recovery on "
              f"{c['on'] * 1e6:.0f} us, off {c['off'] * 1e6:.0f} us, ratio {c['on'] / c['off']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
