"""How tight, and how cheap, a per-phase scalar bound would be for a Kalman table (a measurement of a
route, not a bound the observer publishes).

The rigorous exact bound steps an ellipsoid ``S`` per sample (``M S M'``, its allowances, an
eigenvalue problem per read: :mod:`switchobs_core.bounds.rigorous`). On a gain table's grid the maps
``M_j`` repeat with the phase ``j``, so a norm can be fixed per phase offline: with ``P_j`` solving
the discounted periodic Lyapunov recursion ``P_j = M_j P_{j-1} M_j' / lambda^2 + D^2`` (``D`` the
balancing, ``lambda = 1 - s (1 - r)`` with ``r`` the per-step contraction of the period's monodromy and
``0 < s < 1`` the ``--slack``),
``c_j = ||P_j^{-1/2} M_j P_{j-1}^{1/2}||_2 < lambda`` and ``h_j = ||P_j^{-1/2} D||_2``, the error obeys
``||e_k||_{P_k} <= beta_k`` with the scalar recursion

    ``beta_k = c_j beta_{k-1} + h_j rho_k``

(``rho_k`` the same residual bound as the ellipsoid's), and ``||e_k|| <= beta_k sqrt(lambda_max(P_j))``:
O(1) per sample after the residual's O(n) norms. The constants are proved in floating point
(:class:`switchobs_core.bounds.phase_norm.PhaseNorms`); the recursion starts at the first periodic
sample from the ellipsoid there and is compared with the ellipsoid's exact bound over the same run,
with the ellipsoid's residuals (the scalar bound's own ``||e||`` would enter them through terms of
order ``u ||e||``); the per-sample cost is the table observer
without the bound plus the residual and the recursion, timed side by side with the reference
filter of ``bench_scale.py``.

``python bench/bench_phase_norm.py --agents 2 8 --seconds 40``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_scale import ReferenceKF, _cost_setup

from switchobs_core.bounds.phase_norm import PhaseNorms, lyapunov_shapes


def _record(system, cycle, table, stream):
    """Run the table observer with the exact bound: per sample ``(t, exact bound, rho, KalmanMap,
    S after the sample (at the first periodic sample only), None, phase key)``."""
    import switchobs_core as so
    from switchobs_core.bounds.kalman_map import KalmanMap
    from switchobs_core.numerics.rounding import ErrorEllipsoid

    got: dict = {}
    sandwich, product = KalmanMap.sandwich, ErrorEllipsoid.propagate_product

    def sandwich_rec(self, ell):
        got["m"] = self
        return sandwich(self, ell)

    def product_rec(self, Z, w, c, rho, mn):
        got["rho"] = rho
        return product(self, Z, w, c, rho, mn)

    KalmanMap.sandwich, ErrorEllipsoid.propagate_product = sandwich_rec, product_rec
    try:
        obs = so.SwitchedObserver(system, table, "periodic", [cycle])
        b = obs._bounds.rigorous
        rows = []
        first = True
        for t, ch, _, y in stream:
            got.clear()
            obs.update(t, ch, y)
            env = obs.envelope(amortised=False)
            g = obs._gains._kgain
            periodic = g is not None and len(g) == 4 and not g[0]
            rows.append((t, env.exact_bound, got.get("rho"), got.get("m"), b.ell.S.copy() if periodic and first
                         else None, None, g))
            first = first and not periodic
    finally:
        KalmanMap.sandwich, ErrorEllipsoid.propagate_product = sandwich, product
    return rows, b.d


def tightness(M: int, seconds: float, slack: float) -> dict:
    """The scalar bound against the ellipsoid's over one run of ``camera_agents(M)`` (module docstring)."""
    rate_hz = 50.0
    system, cycle, table, stream = _cost_setup(M, int(seconds * rate_hz), 1.0, rate_hz)
    rows, d = _record(system, cycle, table, stream)
    per = [i for i, r in enumerate(rows) if r[6] is not None and len(r[6]) == 4 and not r[6][0]]
    k0 = per[0]
    N = next(i for i in per[1:] if rows[i][6][1] == rows[k0][6][1]) - k0
    Ms = [rows[k0 + j][3].E for j in range(N)]          # phase j: the map into sample k0 + j
    mono = np.eye(system.n)
    for j in range(1, N + 1):
        mono = Ms[j % N] @ mono
    step_rate = float(max(abs(np.linalg.eigvals(mono)))) ** (1.0 / N)
    lam = 1.0 - (1.0 - step_rate) * slack
    c0 = time.process_time()
    pn = PhaseNorms(Ms, lyapunov_shapes(Ms, d, lam), d)      # every constant proved
    const_s = time.process_time() - c0
    beta = pn.start(rows[k0][4], 0)
    ratios = []
    for k in range(k0 + 1, len(rows)):
        j = (k - k0) % N
        beta = pn.step(beta, j, rows[k][2])
        ratios.append(pn.bound(beta, j) / rows[k][1])
    ratios = np.array(ratios)
    return {"n": system.n, "period": N, "start": rows[k0][0], "step_rate": step_rate, "lambda": lam,
            "c_max": float(pn.c.max()), "cond": float(max(np.linalg.cond(Pj) for Pj in pn.shapes)),
            "ratio_median": float(np.median(ratios)), "ratio_max": float(ratios.max()),
            "ratio_last_period": float(np.median(ratios[-N:])), "pn": pn, "k0": k0,
            "const_s": const_s}


def cost(M: int, samples: int, block: int, consts: dict) -> dict:
    """Median CPU us per sample once every phase was visited: the node pattern (update +
    envelope()) with the exact bound, the table without the bound plus the scalar bound's residual
    and recursion, and the reference filter."""
    import switchobs_core as so
    from switchobs_core.bounds.rigorous import RoundingBound

    pn, k0 = consts["pn"], consts["k0"]         # k0: the first periodic sample
    warm = k0 + len(pn.c)                       # every phase visited once
    system, cycle, table, stream = _cost_setup(M, warm + samples, 1.0)
    noise = so.default_noise(system)
    node = so.SwitchedObserver(system, table, "periodic", [cycle])
    bare = so.SwitchedObserver(system, table, "periodic", [cycle], rounding_bound=False)
    rb = RoundingBound(np.asarray(system.A, float), max(system.p), 1.0, None, scale=node._bounds.rigorous.d)
    ref = ReferenceKF(np.asarray(system.A, float), noise.Q_c, noise.P0, noise.R(1))
    N = len(pn.c)
    state = {"beta": 1.0, "x": None}
    fam = bare._gains

    def scalar(k):
        t, ch, H, y = stream[k]
        x0 = state["x"]
        x = bare.update(t, ch, y)
        bare.envelope()
        g = fam._kgain
        m = fam._fused.get((g[0], g[1], ch, 20_000_000)) if x0 is not None and len(g) == 4 else None
        state["x"] = x.copy()
        if m is None:
            return None
        # the fused step's residual (the same arithmetic as RoundingBound.fused) from the scalar bound;
        # x^- and nu taken again here (the observer's map carries them: an over-estimate of the cost)
        xm = m.predict(x0)
        nu = y - H @ xm
        xs, xs1 = rb.xn(x0), rb.xn(xm)
        j = (k - k0) % N
        en = pn.balanced(state["beta"], j)
        rc = rb.rho_correct(m.fK, m.fH, xm, y, nu, x, xs1)
        rho = m.nIKH * rb._rho_step(m.e, 0.02, xs, xs1, en, None, None) + rc + m.emap * en
        state["beta"] = pn.step(state["beta"], j, rho)
        return pn.bound(state["beta"], j)

    est = {
        "kalman table + envelope() (the node, ellipsoid)": lambda k: (node.update(*stream[k][:2], stream[k][3]),
                                                                       node.envelope()),
        "kalman table, no bound, + scalar bound (estimate)": scalar,
        "reference Kalman filter (standard form, numpy)": lambda k: ref.update(stream[k][0], stream[k][2],
                                                                               stream[k][3]),
    }
    names = list(est)
    times: dict = {name: [] for name in names}
    for k in range(warm):       # first visits (the maps' norms, the exponentials) not timed
        for f in est.values():
            f(k)
    for b, start in enumerate(range(warm, warm + samples - block + 1, block)):
        for name in names[b % 3:] + names[: b % 3]:
            f = est[name]
            t0 = time.process_time_ns()
            for k in range(start, start + block):
                f(k)
            times[name].append((time.process_time_ns() - t0) / block / 1e3)
    return {"n": system.n, "median_us": {k: float(np.median(v[2:])) for k, v in times.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[2, 8])
    ap.add_argument("--seconds", type=float, default=40.0, help="simulated seconds per n (tightness)")
    ap.add_argument("--slack", type=float, default=0.5,
                    help="lambda = 1 - slack (1 - r), r the monodromy's per-step contraction")
    ap.add_argument("--samples", type=int, default=1000, help="samples per n (cost)")
    ap.add_argument("--block", type=int, default=25)
    a = ap.parse_args(argv)
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    load0 = os.getloadavg()[0]
    lines = ["| n | period (samples) | periodic from | per-step rate | lambda | max c_j | max cond P_j "
             "| scalar / ellipsoid bound: median | max | last period | shapes and proofs (CPU) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    cost_rows = []
    for M in a.agents:
        r = tightness(M, a.seconds, a.slack)
        lines.append(f"| {r['n']} | {r['period']} | {r['start']:.2f} s | {r['step_rate']:.5f} | {r['lambda']:.5f} "
                     f"| {r['c_max']:.5f} | {r['cond']:.3g} | {r['ratio_median']:.2f} | {r['ratio_max']:.2f} "
                     f"| {r['ratio_last_period']:.2f} | {r['const_s']:.1f} s |")
        print(lines[-1], file=sys.stderr, flush=True)
        cost_rows.append(cost(M, a.samples, a.block, r))
    names = list(cost_rows[0]["median_us"])
    lines += ["", "| us per sample (median) | " + " | ".join(f"n = {r['n']}" for r in cost_rows) + " |",
              "|---|" + "---|" * len(cost_rows)]
    for name in names:
        lines.append(f"| {name} | " + " | ".join(f"{r['median_us'][name]:.1f}" for r in cost_rows) + " |")
    ref = names[-1]
    for name in names[:-1]:
        lines.append(f"| ratio: {name} / reference | "
                     + " | ".join(f"{r['median_us'][name] / r['median_us'][ref]:.2f}" for r in cost_rows) + " |")
    print(f"load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
