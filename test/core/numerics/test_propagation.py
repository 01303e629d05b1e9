"""Tests of switchobs_core.numerics.propagation: exact ZOH pairs, Van Loan, the LRU cache."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.exceptions import InvalidArgument
from switchobs_core.numerics.propagation import ZOHCache, quantize_dt, van_loan, zoh_pair


def test_zoh_pair_scalar_closed_form():
    a, dt = -1.7, 0.3
    Phi, Gamma = zoh_pair([[a]], dt)
    assert Phi[0, 0] == pytest.approx(math.exp(a * dt), rel=1e-14)
    assert Gamma[0, 0] == pytest.approx((math.exp(a * dt) - 1) / a, rel=1e-13)


def test_zoh_pair_double_integrator_closed_form():
    dt = 0.37
    Phi, Gamma = zoh_pair([[0.0, 1.0], [0.0, 0.0]], dt)
    np.testing.assert_allclose(Phi, [[1, dt], [0, 1]], atol=1e-15)
    np.testing.assert_allclose(Gamma, [[dt, dt ** 2 / 2], [0, dt]], atol=1e-15)


def test_zoh_pair_solves_forced_system():
    # x(dt) = e^{M dt} x0 + M^{-1}(e^{M dt} - I) w for invertible M
    rng = np.random.default_rng(1)
    M = rng.standard_normal((4, 4)) - 3 * np.eye(4)
    x0, w, dt = rng.standard_normal(4), rng.standard_normal(4), 0.21
    Phi, Gamma = zoh_pair(M, dt)
    E = expm(M * dt)
    np.testing.assert_allclose(Phi @ x0 + Gamma @ w, E @ x0 + np.linalg.solve(M, (E - np.eye(4)) @ w),
                               rtol=1e-12, atol=1e-14)


def test_van_loan_scalar_closed_form():
    a, q, dt = -0.8, 2.5, 0.4
    F, Qd = van_loan(np.array([[a]]), np.array([[q]]), dt)
    assert F[0, 0] == pytest.approx(math.exp(a * dt), rel=1e-14)
    assert Qd[0, 0] == pytest.approx(q * (math.exp(2 * a * dt) - 1) / (2 * a), rel=1e-12)


def test_cache_hits_misses_and_products():
    M = np.array([[0.0, 1.0], [-2.0, -0.5]])
    L = np.array([[1.0], [0.5]])
    B = np.array([[0.0], [1.0]])
    c = ZOHCache(maxsize=2)
    c.register("g", M, L, B)
    e1 = c.step("g", 0.01)
    e2 = c.step("g", 0.01 + 1e-16)  # float jitter -> same quantised step
    assert e1 is e2 and c.hits == 1 and c.misses == 1
    Phi, Gamma = zoh_pair(M, 0.01)
    np.testing.assert_allclose(e1.Phi, Phi, rtol=1e-14)
    np.testing.assert_allclose(e1.GL, Gamma @ L, rtol=1e-14)
    np.testing.assert_allclose(e1.GB, Gamma @ B, rtol=1e-14)
    c.step("g", 0.02)
    c.step("g", 0.03)  # evicts 0.01 (least recently used)
    assert len(c) == 2
    c.step("g", 0.01)
    assert c.misses == 4


def test_cache_quantisation():
    assert quantize_dt(0.0100000000004, 1e-9) == pytest.approx(0.01, abs=1e-18)
    assert quantize_dt(0.123, None) == 0.123


@pytest.mark.parametrize("kw,match", [({"maxsize": 0}, "maxsize"), ({"dt_resolution": -1.0}, "dt_resolution")])
def test_cache_bad_arguments(kw, match):
    with pytest.raises(InvalidArgument, match=match):
        ZOHCache(**kw)


@settings(max_examples=40, deadline=None)
@given(dt=st.floats(1e-4, 0.5), seed=st.integers(0, 1000))
@example(dt=0.4453125, seed=829)     # scipy's expm beyond the model there: the base's eps is measured
def test_composed_steps_are_exact_within_their_eps(dt, seed):
    """A step off the composition grid (a jittered sensor period) is e^{M a} e^{M r} with the short
    factor by Taylor: within its certified eps of the extended-precision exponential, and that eps
    stays at the rounding level (so the exact bound keeps its floor)."""
    from switchobs_core.numerics.propagation import split_step
    from switchobs_core.numerics.rounding import expm_extended

    rng = np.random.default_rng(seed)
    M = rng.standard_normal((5, 5)) * 3.0
    c = ZOHCache()
    c.register("g", M, rng.standard_normal((5, 2)), None)
    e = c.step("g", dt)
    qc, r = split_step(e.dt, c.dt_resolution)
    ref = np.asarray(expm_extended(M, e.dt), dtype=float)
    diff = float(np.linalg.norm(e.Phi - ref))
    assert diff <= e.eps
    if qc > 0 and r > 0:        # composing adds only the short step's rounding to the grid step's error
        base = c._lru[("g", "grid", qc)]
        assert e.eps <= 3 * base.eps + 1e-12 * float(np.linalg.norm(ref))
    if qc > 0 and r > 0:
        Phi, Gamma = zoh_pair(M, e.dt)
        np.testing.assert_allclose(e.GL, Gamma @ c._gains["g"][1], rtol=1e-10, atol=1e-13)
