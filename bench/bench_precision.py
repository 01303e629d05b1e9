#!/usr/bin/env python
"""Double precision at design time and at run time: what is refused, how the 32-agent camera model
runs, and the square-root online recursion against the Joseph form.

    python bench/bench_precision.py              # everything (a few minutes CPU, one BLAS thread)
    python bench/bench_precision.py --out FILE   # also write the markdown section to FILE

1. Design time (``design_kalman``, the LMI ``Designer``): the camera model with 32 agents whose
   modes grow with the agent (0.1 + 0.03 (j - 2) per second for agent j >= 3, up to 1/s: the
   former default of ``camera_agents``), every h_i = 1 s, 50 Hz, is refused: the one line and the
   CPU time to it. The periodic covariance's span (largest over smallest eigenvalue over the
   period's priors, :mod:`switchobs_core.design.precision`) of the designs that are accepted: the
   paper's model, 8 agents and the built-in 32 agents (``camera_agents`` as it is), and 32 agents
   whose velocity modes are all 0.05/s; CPU time of each design.
2. Run time, 32 agents (the tables of 1), 1 mm noise, the plant noise-free from a random state
   (seed 1), estimate from zero: stamps on the 50 Hz grid or jittered by up to 1 ms (uniform; the
   plant sampled at the stamp, its channel the schedule's at the stamp). Exceptions, the error at
   30 s and its largest ratio to the state's norm over the last period, and the RMS error over the
   last period (64-96 s) against the same run on the grid; the ``kalman`` table (a jittered stamp
   leaves its cache: the online recursion runs from there) and ``kalman-online``.
3. The square-root recursion against the Joseph form: ``kalman-online`` (a factor, QR array) and
   the standalone filter of ``runtime/kalman_online.py`` (covariance form, Joseph update) on the
   same samples (the first at t0), 60 s with 1 ms jitter: the largest difference of the estimates
   (relative to the estimate's norm, at least 1) and of the covariances (relative to its 2-norm),
   on the paper's model (50 Hz) and on a stiff system (modes -200/s beside slow unstable ones,
   1 um noise, 100 Hz).

The cost per sample of ``kalman-online`` is measured by ``bench/bench_scale.py --cost``.
A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from bench_design import machine_info  # the one machine description of the benchmarks
from scipy.linalg import expm

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "test" / "core")]

from switchobs_core.threads import single_threaded_blas  # noqa: E402

single_threaded_blas()

from _systems import stiff_pair  # noqa: E402  (the stiff system test_online_sqrt.py checks)

import switchobs_core as so  # noqa: E402
from switchobs_core.design.precision import covariance_span  # noqa: E402
from switchobs_core.runtime.kalman_online import OnlineKalman  # noqa: E402

M = 32
RATE = 50.0


def growing(m: int):
    """The former default: agent j >= 3 with the velocity mode 0.1 + 0.03 (j - 2) per second."""
    return so.camera_agents(m, D_agents=[(0.0, 0.2), (0.0, 0.1)] + [(0.0, 0.1 + 0.03 * (j - 2))
                                                                     for j in range(3, m + 1)])


def slow(m: int):
    return so.camera_agents(m, D_agents=[(0.0, 0.05)] * m)


def refusals() -> list[dict]:
    out = []
    for what, call in (("Kalman", lambda: so.design_kalman(growing(M), so.Cycle([1.0] * M), RATE)),
                       ("LMI", lambda: so.Designer(growing(M)).design(so.Cycle([1.0] * M)))):
        t = time.process_time()
        try:
            call()
            msg = "accepted"
        except so.PrecisionError as err:
            msg = str(err)
        out.append({"what": what, "cpu": time.process_time() - t, "msg": msg})
    return out


def designs() -> dict:
    cases = {"paper (2, 0.6) s": (so.paper_system(), so.Cycle.from_ts(2.0, 0.6)),
             "8 agents (built-in), h_i = 1 s": (so.camera_agents(8), so.Cycle([1.0] * 8)),
             "32 agents (built-in), h_i = 1 s": (so.camera_agents(M), so.Cycle([1.0] * M)),
             "32 agents at 0.05/s, h_i = 1 s": (slow(M), so.Cycle([1.0] * M))}
    out = {}
    for name, (system, cycle) in cases.items():
        t = time.process_time()
        kd = so.design_kalman(system, cycle, RATE)
        cpu = time.process_time() - t
        out[name] = {"system": system, "cycle": cycle, "kd": kd, "cpu": cpu,
                     "span": covariance_span(system, [ph.P_prior for ph in kd.periodic]).span}
    return out


def run32(system, cycle, kd, family: str, jitter: float, seconds: float) -> dict:
    """One run of item 2: the noise and the initial state the same for every run, the jitter its own draws."""
    table = so.kalman_table(system, [kd])
    obs = so.SwitchedObserver(system, table, cycles=[cycle], family=None if family == "kalman" else family,
                              rounding_bound=False)
    sch = so.PeriodicSchedule(cycle)
    rng, jit = np.random.default_rng(1), np.random.default_rng(2)
    x, tp, grid = rng.normal(size=system.n), 0.0, expm(system.A / RATE)
    err, norm, ts, exc = [], [], [], ""
    cpu = 0.0
    for k in range(int(seconds * RATE)):
        t = k / RATE + (float(jit.uniform(-jitter, jitter)) if k and jitter else 0.0)
        if k:
            x = (grid if t - tp == 1.0 / RATE else expm(system.A * (t - tp))) @ x
        tp = t
        ch = sch.channel_at(t)
        y = system.C[ch - 1] @ x + 1e-3 * rng.normal(size=system.p[ch - 1])
        c0 = time.process_time()
        try:
            xh = obs.update(t, ch, y)
        except so.SwitchobsError as e:
            exc = f"{type(e).__name__} at {t:.3f} s: {e}"
            break
        cpu += time.process_time() - c0
        err.append(float(np.linalg.norm(xh - x)))
        norm.append(float(np.linalg.norm(x)))
        ts.append(t)
    e, nx, ts = np.array(err), np.array(norm), np.array(ts)
    last = ts >= seconds - cycle.tau
    i30 = int(np.searchsorted(ts, 30.0))
    return {"exc": exc, "e30": e[i30] if i30 < len(e) else np.nan, "x30": nx[i30] if i30 < len(e) else np.nan,
            "rel_last": float(np.max(e[last] / nx[last])) if np.any(last) else np.nan,
            "rms_last": float(np.sqrt(np.mean(e[last] ** 2))) if np.any(last) else np.nan,
            "samples": len(ts), "cpu": cpu, "departures": obs.kalman_departures}


def versus_joseph(system, noise, cycle, rate: float, seconds: float = 60.0) -> dict:
    obs = so.SwitchedObserver(system, None, mode="robust", bounds=(0.1, 100.0), family="kalman-online", noise=noise,
                              rounding_bound=False)
    ref = OnlineKalman(system, noise)
    sch = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(5)
    x, tp, dx, dP = rng.normal(size=system.n), 0.0, 0.0, 0.0
    for k in range(int(seconds * rate)):
        t = k / rate + (float(rng.uniform(-1e-3, 1e-3)) if k else 0.0)
        x = expm(system.A * (t - tp)) @ x
        tp = t
        ch = sch.channel_at(t)
        y = system.C[ch - 1] @ x + noise.meas_std[ch - 1][0] * rng.normal(size=system.p[ch - 1])
        a, b = obs.update(t, ch, y), ref.update(t, ch, y)
        dx = max(dx, float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1.0)))
        dP = max(dP, float(np.linalg.norm(obs.P - ref.P, 2) / np.linalg.norm(ref.P, 2)))
    return {"dx": dx, "dP": dP}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    info = machine_info()
    lines = [f"Machine: {info['cpu']}, {info['nproc']} cores, Python {info['python']}; commit {info['commit']}; "
             f"load average {info['load'][0]:.1f} before ({info['date']}).",
             "Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_precision.py`.", ""]
    lines += ["| design refused | CPU to the refusal | the line |", "|---|---|---|"]
    for r in refusals():
        lines.append(f"| {r['what']}, 32 growing agents | {r['cpu']:.2f} s | {r['msg']} |")
    lines += ["", "| Kalman design accepted (50 Hz) | periodic covariance span | design CPU |", "|---|---|---|"]
    ds = designs()
    for name, d in ds.items():
        lines.append(f"| {name} | {d['span']:.3g} | {d['cpu']:.1f} s |")
    lines += ["", "| 32 agents | family | stamps | exception | error at 30 s (state norm) | largest error / state "
              "norm, last period | RMS error, last period | ratio to the grid |", "|---|---|---|---|---|---|---|---|"]
    for name in ("32 agents at 0.05/s, h_i = 1 s", "32 agents (built-in), h_i = 1 s"):
        d = ds[name]
        for family in ("kalman", "kalman-online"):
            runs = {j: run32(d["system"], d["cycle"], d["kd"], family, j, 96.0) for j in (0.0, 1e-3)}
            for j, r in runs.items():
                stamps = "grid" if j == 0 else "1 ms jitter"
                lines.append(f"| {name.split(',')[0]} | {family} | {stamps} | "
                             f"{r['exc'] or 'none'} | {r['e30']:.3g} ({r['x30']:.3g}) | {r['rel_last']:.3g} | "
                             f"{r['rms_last']:.4g} | {r['rms_last'] / runs[0.0]['rms_last']:.3f} |")
    sysm, stiff_noise = stiff_pair()
    vj = {"paper, 50 Hz": versus_joseph(so.paper_system(), so.default_noise(so.paper_system()),
                                        so.Cycle.from_ts(2.0, 0.6), 50.0),
          "stiff, 100 Hz": versus_joseph(sysm, stiff_noise, so.Cycle.from_ts(2.0, 0.5), 100.0)}
    lines += ["", "| square root vs Joseph, 60 s, 1 ms jitter | largest estimate difference / norm | largest "
              "covariance difference / norm |", "|---|---|---|"]
    for name, r in vj.items():
        lines.append(f"| {name} | {r['dx']:.2g} | {r['dP']:.2g} |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
