"""The bound audit across units, stiffness, float stamps and channel counts: systems, truth, runner.

Shared by test_units_audit.py (short runs, and five simulated minutes marked ``slow``) and
bench/bench_units.py (the figures of bench/RESULTS.md). The truth is the plant in ``np.longdouble``
(x87 80-bit: unit roundoff 5.4e-20), propagated in the balanced coordinates of ``A`` (a power-of-two
diagonal similarity, exact) by ``_extended_truth.Truth``, twice (``m`` and ``m + 1`` substeps) for its
own error ``delta``; each output is ``C x`` rounded once to double.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from _extended_truth import Truth
from _systems import chain, dense40, in_units, oscillator_si, sparse40, wide_units

import switchobs_core as so

LD = np.longdouble


@dataclass(frozen=True)
class AuditSystem:
    system: so.LTISystem
    cycle: so.Cycle
    rate: float
    x0: np.ndarray
    families: tuple[str, ...]
    stamps: str = "grid"        # grid | jitter (+-30 % of a period, float stamps off the 1 ns grid)
    noise: so.NoiseModel | None = None


def systems() -> dict[str, AuditSystem]:
    """The audit's systems (test_units_audit.py's module docstring)."""
    osc = oscillator_si()
    ocyc = so.Cycle((0.3, 0.2))         # 0.3 s = 60 samples at 200 Hz: ties at every switch
    ox0 = np.array([0.01, 0.3, -0.02, 0.1])
    x40 = np.random.default_rng(4).uniform(-1, 1, 40)
    return {
        "oscillator_si": AuditSystem(osc, ocyc, 200.0, ox0, ("kalman",)),
        "oscillator_si_jitter": AuditSystem(osc, ocyc, 200.0, ox0, ("kalman", "kalman-online"), stamps="jitter"),
        "wide_units_2": AuditSystem(wide_units(2.0), so.Cycle((0.6, 0.4)), 50.0, np.logspace(-2, 2, 4),
                                    ("kalman",)),
        "wide_units_3": AuditSystem(wide_units(3.0), so.Cycle((0.6, 0.4)), 50.0, np.logspace(-3, 3, 4),
                                    ("kalman",)),
        "dense40": AuditSystem(dense40(), so.Cycle((0.6, 0.4)), 50.0, x40, ("kalman",)),
        "sparse40": AuditSystem(sparse40(), so.Cycle((0.6, 0.4)), 50.0, x40, ("kalman",)),
        "chain3": AuditSystem(chain(3), so.Cycle((0.3, 0.2, 0.1)), 50.0, np.array([0.1, 0, -0.2, 0.5, 0.3, 0]),
                              ("kalman",)),
        "chain4": AuditSystem(chain(4), so.Cycle((0.25, 0.15, 0.35, 0.1)), 40.0,
                              np.array([0.1, 0, -0.2, 0.5, 0.3, 0, 0.05, -0.4]), ("kalman",)),
    }


def in_other_units(a: AuditSystem, T: np.ndarray) -> AuditSystem:
    """The same system, noise model and initial state with state ``i`` in units ``T_i`` times smaller."""
    T = np.asarray(T, dtype=float)
    base = so.NoiseModel.for_system(a.system)
    noise = so.NoiseModel.for_system(in_units(a.system, T), process_intensity=base.Q_c * np.outer(T, T),
                                     P0=base.P0 * np.outer(T, T))
    return AuditSystem(in_units(a.system, T), a.cycle, a.rate, a.x0 * T, a.families, a.stamps, noise)


_TABLES: dict = {}


def table_for(a: AuditSystem, family: str) -> so.GainTable:
    key = (a.system.fingerprint(), family == "lmi", a.rate, None if a.noise is None else a.noise.fingerprint())
    if key not in _TABLES:
        if family == "lmi":
            _TABLES[key] = so.design_table(a.system, cycles=[a.cycle], delta=0.99, progress=False)
        else:
            _TABLES[key] = so.kalman_table(a.system, [so.design_kalman(a.system, a.cycle, a.rate, a.noise)])
    return _TABLES[key]


def stamps(a: AuditSystem, seconds: float) -> list[float]:
    K = int(round(seconds * a.rate)) + 1
    t = np.arange(K) / a.rate
    if a.stamps == "jitter":
        t = t + np.random.default_rng(7).uniform(-0.3, 0.3, K) / a.rate
        t[0] = 0.0
    return [float(v) for v in t]


def audit(a: AuditSystem, family: str, seconds: float, *, every: int = 1, exact_start: bool = False) -> dict:
    """Run ``seconds`` of ``a`` with ``family``: violations of the published exact bound against the
    truth (after every ``every``-th update; the error plus ``4 delta`` counts), whether ``envelope()``
    raised or gave a bound that is not finite, the final bound / error, and the Kalman table's
    departures, re-locks and share of samples served. The estimate starts at zero with ``e0 =
    ||x0||`` (a ball in the user's units), or with ``exact_start`` at ``x0`` itself with ``e0 = 0``
    (the bound is then rounding alone)."""
    system = a.system
    sched = so.PeriodicSchedule(a.cycle)
    e0 = 0.0 if exact_start else float(np.linalg.norm(a.x0)) * (1 + 1e-12)
    kw = {"family": family} if family == "kalman-online" else {}
    obs = so.SwitchedObserver(system, table_for(a, family), "periodic", [a.cycle], e0=e0,
                              x0=a.x0 if exact_start else None, **kw)
    truth = Truth(system.A, a.x0, balanced_coordinates=True)
    C = [np.asarray(Ci, dtype=LD) for Ci in system.C]
    out = {"violations": 0, "checks": 0, "raised": "", "nonfinite": 0, "worst": 0.0, "delta_ratio": 0.0,
           "served": 0, "steady": 0}
    ts = stamps(a, seconds)
    t_prev = 0.0
    start = time.perf_counter()
    err = bound = math.nan
    for k, t in enumerate(ts):
        truth.advance(LD(t) - LD(t_prev))
        t_prev = t
        ch = sched.channel_at(t)
        y = np.asarray(C[ch - 1] @ truth.x, dtype=float)
        xh = obs.update(t, ch, y)
        if k >= len(ts) // 2:
            out["steady"] += 1
            out["served"] += obs.gains_source == "table"
        if k % every and k + 1 < len(ts):
            continue
        try:
            bound = obs.envelope().exact_bound
        except Exception as exc:      # the audit records it: envelope() must never raise
            out["raised"] = out["raised"] or f"{type(exc).__name__} at t = {t}: {exc}"
            continue
        if not math.isfinite(bound):
            out["nonfinite"] += 1
            continue
        err = float(np.linalg.norm((np.asarray(xh, dtype=LD) - truth.x).astype(float)))
        d = truth.delta
        out["checks"] += 1
        out["delta_ratio"] = max(out["delta_ratio"], d / bound if bound > 0 else math.inf)
        out["worst"] = max(out["worst"], (err + 4 * d) / bound if bound > 0 else math.inf)
        out["violations"] += err + 4 * d > bound
    out.update(samples=len(ts), error=err, bound=bound, ratio=bound / max(err, 1e-300), S=obs.prior(obs.t)[1],
               departures=obs.kalman_departures, relocks=obs.kalman_relocks, withdrawn=obs.bounds_withdrawn,
               seconds=time.perf_counter() - start,
               served_fraction=out["served"] / max(out["steady"], 1))
    return out
