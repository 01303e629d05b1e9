"""Tests of switchobs_core.propagation: exact ZOH pairs, Van Loan, the LRU cache."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.exceptions import InvalidArgument
from switchobs_core.propagation import ZOHCache, quantize_dt, van_loan, zoh_pair


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
