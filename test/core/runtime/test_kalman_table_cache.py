"""The ``kalman`` table is an exact cache of the Riccati recursion: whatever the
sample pattern, its estimates are the Kalman filter's and its published ``P`` is the real one.

Checked, through the public API only, against an online Kalman filter written here
(:class:`JosephKF`: exact discretisation by one matrix exponential (van Loan), Joseph-form
correction, symmetrised) that sees the same streams, with the noise model the table was designed
for (``default_noise``: R = (1 mm)^2 I, Q_c = 1e-4 I, P0 = 100 I).

System: two coupled, lightly damped oscillators ``x = [q1, v1, q2, v2]``; channel 1 measures
``q1 + q2`` (the shared row 0) and ``q1``, channel 2 ``q1 + q2`` and ``q2``; periodic cycle
(0.61 s, 0.39 s) at 50 Hz (no sample on a switching instant: the table's pattern is the stream's
whenever every row arrives). Disturbances (one per scenario):

* ``rows3``: only the shared row on the first 3 samples;
* ``partial5``: 5 % of the samples (seeded, per run) carry only the shared row;
* ``drop2``: 2 % of the samples are not delivered, on an unstable variant (1.5 Hz and 2.5 Hz,
  damping ratios -0.05 and 0.01: the first mode grows at 0.47/s); the table stays on its grid
  and carries the covariance's deviation in low rank with the filter's gain
  (:mod:`switchobs_core.runtime.families.gaps`);
* ``set_state``: ``set_estimate`` of ``v1`` at 7.01 s (between two samples), to the true value
  plus N(0, 0.01), with variance 0.01 (so the reset entry's error is independent of the rest,
  which is what zeroing its row and column of ``P`` states).

Criteria: the table's RMS error within 1.05x of the filter's over 0-5 s, at
10 s and over 10-20 s; average NEES ``e' P^-1 e`` (``P`` the published one) inside the chi-square
band at 0.5, 1, 2, 5, 10 and 20 s; the published ``P`` equal to the filter's covariance at every
sample to ``P_RTOL`` of its largest entry.

Statistics. With R runs the average NEES of a consistent filter is chi2(4 R) / R. The band is a
*simultaneous* 95 % band over the m checks of a test (each at two-sided level 0.05 / m,
Bonferroni): a consistent filter passes all of them with probability >= 95 %. (A per-time 95 %
band over 24 checks would fail a consistent filter in ~70 % of seed sets.) The streams are
seeded, so the outcome is deterministic; the filter written here must pass the same band on the
same streams, which checks this test's own model. Power of the slow test (R = 40 runs of 20 s per
scenario, m = 24, band 2.76-5.52): a published covariance too small by a factor 1.5 is caught at a
given check time with probability 0.76 (too large by 1.5: 0.64), by a factor 2 with 0.999; the
quick test (R = 10, m = 4, band 2.12-6.58) catches a factor 3 with 0.99. The RMS ratio is paired
(same streams), so its sampling noise is far below the 5 % margin (a table that runs the
recursion gives 1.000 to 4 digits). The failures of a table that serves its stored gains regardless
(NEES 1e3-1.6e6, RMS 3.9-875x) are far outside. Runtime: about 55 s CPU for the slow test, 2 s for the quick one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from _systems import oscillators
from scipy.linalg import expm
from scipy.stats import chi2

import switchobs_core as so

RATE = 50.0
CYCLE = so.Cycle((0.61, 0.39))
#: Published P vs the filter's, relative to the largest entry of the filter's: the table may
#: re-lock once the real covariance is within its relock tolerance (``relock_rtol``, 1e-3 to 1e-2)
#: of the stored one, after which the two converge (the closed loop contracts); beyond 1e-2, P is
#: not the real one.
P_RTOL = 1e-2
#: Largest RMS ratio table / filter in any window.
RMS_RATIO = 1.05
NEES_TIMES = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
SET_T, SET_INDEX, SET_VAR = 7.01, 1, 0.01


class JosephKF:
    """Online discrete Kalman filter, written independently of ``switchobs_core``.

    Predict over ``dt``: ``F = e^{A dt}``, ``Q_d = int_0^dt e^{A s} Q_c e^{A' s} ds``, both from one
    exponential of van Loan's block matrix ``[[-A, Q_c], [0, A']] dt`` (``F = M22'``,
    ``Q_d = F M12``); ``x <- F x``, ``P <- F P F' + Q_d``. Correct with rows ``H``, noise ``R``:
    ``K = P H' (H P H' + R)^-1``, ``x <- x + K (y - H x)``,
    ``P <- (I - K H) P (I - K H)' + K R K'``, symmetrised.
    """

    def __init__(self, A: np.ndarray, Q_c: np.ndarray, P0: np.ndarray):
        self.A, self.Q_c = np.asarray(A, float), np.asarray(Q_c, float)
        self.n = self.A.shape[0]
        self.x = np.zeros(self.n)
        self.P = np.array(P0, dtype=float)
        self._I = np.eye(self.n)
        self._disc: dict = {}

    def discretize(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        key = round(dt * 1e12)
        hit = self._disc.get(key)
        if hit is None:
            n = self.n
            M = np.zeros((2 * n, 2 * n))
            M[:n, :n], M[:n, n:], M[n:, n:] = -self.A, self.Q_c, self.A.T
            E = expm(M * dt)
            F = E[n:, n:].T
            Qd = F @ E[:n, n:]
            hit = self._disc[key] = (F, 0.5 * (Qd + Qd.T))
        return hit

    def predict(self, dt: float) -> None:
        if dt > 0:
            F, Qd = self.discretize(dt)
            self.x = F @ self.x
            P = F @ self.P @ F.T + Qd
            self.P = 0.5 * (P + P.T)

    def correct(self, H: np.ndarray, R: np.ndarray, y: np.ndarray) -> None:
        PHt = self.P @ H.T
        K = PHt @ np.linalg.inv(H @ PHt + R)
        self.x = self.x + K @ (y - H @ self.x)
        IKH = self._I - K @ H
        P = IKH @ self.P @ IKH.T + K @ R @ K.T
        self.P = 0.5 * (P + P.T)

    def set_entry(self, i: int, value: float, var: float) -> None:
        self.x[i] = value
        self.P[i, :] = 0.0
        self.P[:, i] = 0.0
        self.P[i, i] = var


@dataclass
class Stats:
    """Squared errors of the observer and the filter per (run, sample), NEES at the check times."""

    runs: int
    samples: int
    sq: np.ndarray = field(init=False)
    nees: np.ndarray = field(init=False)
    worst_P: float = 0.0

    def __post_init__(self):
        self.sq = np.full((2, self.runs, self.samples), np.nan)
        self.nees = np.full((2, self.runs, len(NEES_TIMES)), np.nan)


def _pattern(name: str, rng: np.random.Generator, K: int) -> tuple[np.ndarray, np.ndarray]:
    """(delivered, shared_only) flags per sample of a scenario; the first sample is delivered, and
    so is every check time of the NEES (a drop there would leave no posterior to test)."""
    delivered = np.ones(K, bool)
    shared_only = np.zeros(K, bool)
    if name == "rows3":
        shared_only[:3] = True
    elif name == "partial5":
        shared_only[:] = rng.random(K) < 0.05
    elif name == "drop2":
        delivered[:] = rng.random(K) >= 0.02
        delivered[0] = True
        for t in NEES_TIMES:
            if round(t * RATE) < K:
                delivered[round(t * RATE)] = True
    return delivered, shared_only


def run_scenario(system: so.LTISystem, table: so.GainTable, name: str, runs: int, seconds: float,
                 seed: int, rounding_bound: bool = True) -> Stats:
    """Monte Carlo of one scenario: the plant (x0 ~ N(0, P0), exact process noise), the observer
    (``kalman`` table, periodic; its rigorous bound on or off: ``rounding_bound``) and
    :class:`JosephKF` on the same seeded streams."""
    noise = so.default_noise(system)
    A, Qc, P0 = np.asarray(system.A, float), noise.Q_c, noise.P0
    K = int(round(seconds * RATE)) + 1
    st = Stats(runs, K)
    check_k = {round(t * RATE): j for j, t in enumerate(NEES_TIMES) if round(t * RATE) < K}
    sched = so.PeriodicSchedule(CYCLE)
    channels = [sched.channel_at(k / RATE) for k in range(K)]
    HR = {(c, rows): (system.C[c - 1] if rows is None else system.C[c - 1][list(rows)], noise.R(c, rows))
          for c in range(1, system.N + 1) for rows in (None, (0,))}
    plant = JosephKF(A, Qc, P0)           # only its cached discretisation, for the plant
    F, Qd = plant.discretize(1 / RATE)
    LQ = np.linalg.cholesky(Qd)
    for r in range(runs):
        rng = np.random.default_rng([seed, r])
        delivered, shared_only = _pattern(name, rng, K)
        w = rng.standard_normal((K, system.n)) @ LQ.T         # process noise of each grid step
        v = rng.standard_normal((K, max(system.p)))
        x = np.linalg.cholesky(P0) @ rng.standard_normal(system.n)
        obs = so.SwitchedObserver(system, table, "periodic", [CYCLE], rounding_bound=rounding_bound)
        kf = JosephKF(A, Qc, P0)
        t_kf = 0.0
        for k in range(K):
            t = k / RATE
            if name == "set_state" and (k - 1) / RATE < SET_T < t:
                # the plant's step split at SET_T (each half with its own exact noise)
                a = SET_T - (k - 1) / RATE
                Fa, Qa = plant.discretize(a)
                x = Fa @ x + np.linalg.cholesky(Qa) @ rng.standard_normal(system.n)
                value = x[SET_INDEX] + np.sqrt(SET_VAR) * rng.standard_normal()
                obs.set_estimate(SET_T, {SET_INDEX: value}, {SET_INDEX: SET_VAR})
                kf.predict(SET_T - t_kf)
                t_kf = SET_T
                kf.set_entry(SET_INDEX, value, SET_VAR)
                Fb, Qb = plant.discretize(t - SET_T)
                x = Fb @ x + np.linalg.cholesky(Qb) @ rng.standard_normal(system.n)
            elif k:
                x = F @ x + w[k]
            ch = channels[k]
            rows = (0,) if shared_only[k] else None
            H, R = HR[ch, rows]
            y = H @ x + np.sqrt(np.diag(R)) * v[k, :H.shape[0]]
            if not delivered[k]:
                continue
            xo = obs.update(t, ch, y, rows=rows).copy()
            kf.predict(t - t_kf)
            t_kf = t
            kf.correct(H, R, y)
            Po = obs.P
            st.worst_P = max(st.worst_P, float(np.abs(Po - kf.P).max() / np.abs(kf.P).max()))
            for i, (xe, P) in enumerate(((xo, Po), (kf.x, kf.P))):
                e = xe - x
                st.sq[i, r, k] = e @ e
                if k in check_k:
                    st.nees[i, r, check_k[k]] = e @ np.linalg.solve(P, e)
    return st


WINDOWS = {"0-5 s": (0.0, 5.0), "at 10 s": (10.0, 10.0), "10-20 s": (10.0, 20.0)}


def rms_ratios(st: Stats) -> dict[str, float]:
    """Table RMS / filter RMS per window (windows past the run's end are left out)."""
    t = np.arange(st.samples) / RATE
    out = {}
    for w, (a, b) in WINDOWS.items():
        sel = (t >= a - 1e-9) & (t <= b + 1e-9)
        if sel.any():
            ms = np.nanmean(st.sq[:, :, sel], axis=(1, 2))
            out[w] = float(np.sqrt(ms[0] / ms[1]))
    return out


def nees_band(runs: int, n: int, checks: int) -> tuple[float, float]:
    """Simultaneous 95 % band of the average NEES over ``checks`` check times (module docstring)."""
    a = 0.05 / checks
    lo, hi = chi2.ppf([a / 2, 1 - a / 2], runs * n)
    return float(lo / runs), float(hi / runs)


def assert_like_the_filter(st: Stats, name: str, band: tuple[float, float], n: int) -> None:
    ratios = rms_ratios(st)
    assert all(v <= RMS_RATIO for v in ratios.values()), f"{name}: RMS table / filter {ratios}"
    times = [t for t in NEES_TIMES if round(t * RATE) < st.samples]
    mean = np.nanmean(st.nees[:, :, :len(times)], axis=1)
    lo, hi = band
    # the filter written here first: outside the band, this test's own model is wrong
    assert np.all((lo <= mean[1]) & (mean[1] <= hi)), f"{name}: reference filter NEES {mean[1]} outside {band}"
    assert np.all((lo <= mean[0]) & (mean[0] <= hi)), \
        f"{name}: table NEES {dict(zip(times, mean[0].round(3)))} outside {band} (filter: {mean[1].round(3)})"
    assert st.worst_P <= P_RTOL, f"{name}: published P differs from the filter's by {st.worst_P:.3g} of max|P|"


@pytest.fixture(scope="module")
def stable():
    system = oscillators()
    return system, so.kalman_table(system, [so.design_kalman(system, CYCLE, RATE)])


@pytest.fixture(scope="module")
def unstable():
    system = oscillators((-0.05, 0.01), (1.5, 2.5))
    return system, so.kalman_table(system, [so.design_kalman(system, CYCLE, RATE)])


def test_reference_filter_matches_the_library_online_filter(stable):
    """A cross-check of the harness: :class:`JosephKF` and ``kalman-online`` agree on a stream with
    partial rows and a dropped sample (two implementations of one recursion)."""
    system, table = stable
    online = so.SwitchedObserver(system, table, "periodic", [CYCLE], family="kalman-online")
    kf = JosephKF(system.A, so.default_noise(system).Q_c, so.default_noise(system).P0)
    rng = np.random.default_rng(5)
    t_prev = 0.0
    for k in range(100):
        if k == 40:                        # a dropped sample
            continue
        t = k / RATE
        ch = so.PeriodicSchedule(CYCLE).channel_at(t)
        rows = (0,) if k % 7 == 3 else None
        H = system.C[ch - 1] if rows is None else system.C[ch - 1][list(rows)]
        y = rng.standard_normal(H.shape[0])
        online.update(t, ch, y, rows=rows)
        kf.predict(t - t_prev)
        t_prev = t
        kf.correct(H, so.default_noise(system).R(ch, rows), y)
        np.testing.assert_allclose(online.P, kf.P, rtol=1e-9, atol=1e-12 * np.abs(kf.P).max())
        np.testing.assert_allclose(online.x_hat, kf.x, rtol=1e-9, atol=1e-9)


def test_quick_missing_row_at_start(stable):
    """The default run's guard (not slow): 10 runs of 5 s with the shared row alone on the first 3
    samples (a table serving its stored gains regardless: 875x RMS and NEES 1.6e6 at 0.5 s here)."""
    system, table = stable
    runs = 10
    st = run_scenario(system, table, "rows3", runs, 5.0, seed=1)
    band = nees_band(runs, system.n, 4)        # 0.5, 1, 2, 5 s
    assert_like_the_filter(st, "rows3 (quick)", band, system.n)
    # the rigorous bound changes no estimate and no covariance: the same doubles without it (what
    # lets the Monte Carlo below run without it, at half the cost)
    off = run_scenario(system, table, "rows3", runs, 5.0, seed=1, rounding_bound=False)
    assert np.array_equal(off.sq, st.sq, equal_nan=True) and np.array_equal(off.nees, st.nees, equal_nan=True)
    assert off.worst_P == st.worst_P


@pytest.mark.slow
@pytest.mark.parametrize("i, name", list(enumerate(("rows3", "partial5", "drop2", "set_state"))))
def test_monte_carlo_every_disturbance(stable, unstable, i, name):
    """Monte Carlo: 40 runs of 20 s per disturbance, every window and check time (24 NEES
    checks in one simultaneous 95 % band over the four disturbances; module docstring). One
    disturbance a test (the same seeds and band), so that two xdist workers share them."""
    runs = 40
    band = nees_band(runs, 4, 4 * len(NEES_TIMES))
    system, table = unstable if name == "drop2" else stable
    # without the rigorous bound, which this test does not read and which changes no estimate
    # (test_quick_missing_row_at_start checks the same doubles with it; measured on every
    # disturbance here too): half the cost
    st = run_scenario(system, table, name, runs, 20.0, seed=10 + i, rounding_bound=False)
    assert_like_the_filter(st, name, band, system.n)
