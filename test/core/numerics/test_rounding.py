"""The exact bound with rounding (switchobs_core.numerics.rounding): it bounds the error of the *computed*
estimate against the true state for long runs, with every gain family, at sample times that are
not whole nanoseconds, and it stays tight where rounding does not matter."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

import switchobs_core as so
from switchobs_core.numerics.expm_bound import certify_zoh, expm_error_bound
from switchobs_core.numerics.rounding import ErrorEllipsoid, expm_extended, verify_against_extended

PER = [so.Cycle.from_ts(2.0, 0.6)]
SEQ = [so.Cycle.from_ts(4, 0.5), so.Cycle.from_ts(3, 0.6), so.Cycle.from_ts(3, 0.6), so.Cycle.from_ts(2, 0.4)]
X0 = np.array([0, 0, 0.2, 0.1, 3, 1, -0.1, 0, -2, 2, 0.1, 0], dtype=float)


def test_expm_extended_and_error_bound(paper):
    for dt in (0.01, 1 / 30, 0.5):
        Phi = expm(paper.A * dt)
        ref = expm_extended(paper.A, dt)
        diff = float(np.linalg.norm((np.asarray(Phi, np.longdouble) - ref).astype(float), 2))
        assert diff <= 1e-14 * np.linalg.norm(Phi)
        cert = certify_zoh(paper.A, dt)
        bound = expm_error_bound(Phi, cert.E, cert.dE)
        assert diff <= bound <= 1e-13, (dt, diff, bound)


def _random_start(seed: int, n: int = 5, e0: float = 0.7):
    """(rng, n, ellipsoid with S_0 = e0^2 I, an initial error of norm e0)."""
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n)
    return rng, n, ErrorEllipsoid(n, e0), e * (e0 / np.linalg.norm(e))


def _random_step(rng, n: int, rho: float):
    """A random error map (contracting or expanding) and a residual of norm rho."""
    M = rng.standard_normal((n, n)) * rng.uniform(0.1, 1.2) / np.sqrt(n)
    r = rng.standard_normal(n)
    return M, rho * r / np.linalg.norm(r)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), steps=st.integers(1, 30), rho=st.floats(0.0, 1e-3))
def test_ellipsoid_contains_every_reachable_error(seed, steps, rho):
    """Property: e <- M e + r with ||r|| <= rho, ||e_0|| <= e0: ||e_k|| <= bound() at every step."""
    rng, n, ell, e = _random_start(seed)
    for _ in range(steps):
        M, r = _random_step(rng, n, rho)
        e = M @ e + r
        ell.step(M, rho)
        assert np.linalg.norm(e) <= ell.bound()


def test_without_rounding_it_is_the_transition_norm():
    rng = np.random.default_rng(0)
    ell = ErrorEllipsoid(4, 2.0)
    Phi = np.eye(4)
    for _ in range(50):
        M = rng.standard_normal((4, 4)) / 2
        ell.step(M, 0.0)
        Phi = M @ Phi
    assert ell.bound() == pytest.approx(np.linalg.norm(Phi, 2) * 2.0, rel=1e-12)
    assert ell.bound() >= np.linalg.norm(Phi, 2) * 2.0


def _long_run(system, obs, schedule, rate, seconds):
    """(violations, samples, worst error/bound, final bound/error) against the extended-precision truth."""
    r = verify_against_extended(system, obs, schedule, rate, seconds, X0)
    return r["violations"], r["samples"], r["worst"], r["bound"] / max(r["error"], 1e-300)


@pytest.fixture(scope="module")
def lmi_table(paper):
    return so.design_table(paper, cycles=PER + SEQ, delta=0.99, progress=False)


@pytest.mark.parametrize("family,mode,cycles", [("lmi", "periodic", PER), ("lmi", "sequence", SEQ),
                                                ("kalman", "periodic", PER), ("kalman", "sequence", SEQ)])
def test_bound_holds_for_minutes_of_an_unstable_plant(paper, lmi_table, family, mode, cycles):
    """Three simulated minutes at 100 Hz (the unstable agents grow ||x|| to about 50; the exact-
    arithmetic bound ||Phi|| e0 falls below the computed error within a minute): no violation."""
    table = lmi_table if family == "lmi" else so.kalman_table(paper, [so.design_kalman(paper, cycles, 100.0)])
    obs = so.SwitchedObserver(paper, table, mode, cycles, x0=np.zeros(12), e0=10.0)
    sched = so.PeriodicSchedule(cycles[0]) if mode == "periodic" else so.SequenceSchedule(cycles)
    viol, n, worst, final_ratio = _long_run(paper, obs, sched, 100.0, 180.0)
    assert viol == 0, (viol, n, worst)
    assert float(np.linalg.norm(obs.Phi, 2)) * 10.0 < 1e-12     # the old bound alone would be far too small
    assert final_ratio < 1e6                                    # and the new one stays informative


def test_sample_times_that_are_not_whole_nanoseconds(paper, lmi_table):
    """t_k = k/30: the observer's step quantum (1 ns) enters the bound, which holds for minutes,
    and predict(t) stays within envelope(t) between samples."""
    obs = so.SwitchedObserver(paper, lmi_table, "periodic", PER, x0=np.zeros(12), e0=10.0)
    viol, n, worst, _ = _long_run(paper, obs, so.PeriodicSchedule(PER[0]), 30.0, 120.0)
    assert viol == 0, (viol, worst)
    t = obs.t + 0.0123456789
    x_true = np.asarray(expm_extended(paper.A, t), dtype=float) @ X0
    assert np.linalg.norm(obs.predict(t, hold=True) - x_true) <= obs.envelope(t).exact_bound


def test_zero_initial_error_bound_is_not_zero(paper, lmi_table):
    """e0 = 0 (the estimate starts at the truth): the bound is the rounding's, never below the error."""
    obs = so.SwitchedObserver(paper, lmi_table, "periodic", PER, x0=X0, e0=0.0)
    viol, n, worst, _ = _long_run(paper, obs, so.PeriodicSchedule(PER[0]), 100.0, 20.0)
    assert viol == 0 and obs.envelope().exact_bound > 0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), steps=st.integers(1, 30), rho=st.floats(0.0, 1e-3),
       c=st.floats(0.0, 4.0), p=st.integers(1, 3))
def test_shaped_ellipsoid_contains_every_noisy_error(seed, steps, rho, c, p):
    """Property: e <- M e + G v + r with ||v||^2 <= c, ||r|| <= rho: ||e_k|| <= bound() at every
    step, with v at the extremes (the worst case for a fixed direction)."""
    rng, n, ell, e = _random_start(seed)
    for _ in range(steps):
        M, r = _random_step(rng, n, rho)
        G = rng.standard_normal((n, p))
        # the worst v for this step: along the top right singular vector of G, aligned with M e
        v = np.linalg.svd(G)[2][0]
        v *= np.sqrt(c) * np.sign(float((G @ v) @ (M @ e)) or 1.0)
        e = M @ e + G @ v + r
        ell.step_shaped(M, rho, G, c)
        assert np.linalg.norm(e) <= ell.bound()


@pytest.mark.parametrize("family", ["lmi", "kalman"])
def test_noise_bound_holds_under_bounded_noise(paper, lmi_table, family):
    """Two simulated minutes at 100 Hz with noise at the corners of a declared 1 mm box: the
    noise bound holds at every sample, while the noise-free exact bound is soon far below the
    error (so it is published as noise-free, never as a guarantee); the noise bound stays
    within 100x of the error that random corner noise produces."""
    table = lmi_table if family == "lmi" else so.kalman_table(paper, [so.design_kalman(paper, PER, 100.0)])
    obs = so.SwitchedObserver(paper, table, "periodic", PER, x0=np.zeros(12), e0=10.0, noise_max=1e-3)
    r = verify_against_extended(paper, obs, so.PeriodicSchedule(PER[0]), 100.0, 120.0, X0,
                                noise_max=1e-3, seed=3)
    assert r["violations"] == 0, r["worst"]
    env = obs.envelope()
    assert env.exact_bound < 1e-3 * r["error"] < r["error"] <= env.noise_bound < 100 * r["error"]


def test_noise_max_is_checked(paper, lmi_table):
    for bad in (-1.0, float("nan"), True, [1e-3, 1e-3, 1e-3], "x"):
        with pytest.raises(so.InvalidArgument, match="noise_max"):
            so.SwitchedObserver(paper, lmi_table, "periodic", PER, noise_max=bad)
    with pytest.raises(so.InvalidArgument, match="rounding_bound"):
        so.SwitchedObserver(paper, lmi_table, "periodic", PER, noise_max=1e-3, rounding_bound=False)
    per_channel = so.SwitchedObserver(paper, lmi_table, "periodic", PER, noise_max=[1e-3, 2e-3])
    assert per_channel.noise_max == (1e-3, 2e-3)
    assert so.SwitchedObserver(paper, lmi_table, "periodic", PER).envelope().noise_bound is None
