"""The exact set's step through a dense map in few array operations
(:meth:`switchobs_core.numerics.rounding.ErrorEllipsoid.step_dense`) against the general one
(``propagate_product`` of ``M S M'`` with ``image_bound(|M|)``), on both of its paths (the compiled
kernel, numpy): the same set up to the rounding of ``M S M'`` and the allowances (entrywise within
``2 gamma_{2n+2} |M| |S| |M'|`` plus the diagonal allowance; about 1e-13 of the diagonal for a map near a
contraction and ``S`` of full rank, hypothesis over sizes, units, scales and residuals, not in general:
a rank-one ``S`` through a Gaussian map), exactly symmetric, containing the exact product (extended
precision); overflow and NaN withdraw the set; and an observer with a Kalman table publishes the same exact
and noise bounds with it as with the general path (within 1e-12 relative)."""

from __future__ import annotations

import math
from contextlib import nullcontext

import numpy as np
import pytest
from _dense_cases import allowance_ratio, pair
from hypothesis import example, given, settings
from hypothesis import strategies as st

import switchobs_core as so
from switchobs_core.bounds.kalman_map import KalmanMap
from switchobs_core.bounds.rigorous import RoundingBound
from switchobs_core.numerics import dense_kernel
from switchobs_core.numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid

LD = np.longdouble
#: Entrywise tolerance of the fast set against the general one, relative to ``sqrt(S_ii S_jj)`` of the
#: general set, for :func:`pair`'s well-conditioned cases: the two round the same quantities in another
#: order and fold the allowance's factors into its coefficients (``(1 + 16 u)``); 1e-13 is about 450 ``u``.
#: In general the bound is the allowance (:func:`allowance_ratio`, the rank-one test below).
RTOL = 1e-13
#: ``step_dense``'s two paths: the compiled kernel (where built) and numpy (the kernel set aside).
PATHS = [pytest.param(True, id="kernel", marks=pytest.mark.skipif(not dense_kernel.available(),
                                                                 reason="the compiled kernel is not built")),
         pytest.param(False, id="numpy")]


def _path(kernel: bool):
    return nullcontext() if kernel else dense_kernel.numpy_step()


@pytest.mark.parametrize("kernel", PATHS)
@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 30), rho=st.sampled_from([0.0, 1e-300, 1e-16, 1e-9, 1e-3, 10.0]),
       units=st.booleans(), scale=st.floats(1e-30, 1e30))
def test_fast_step_is_the_general_set(kernel, seed, n, rho, units, scale):
    M, S, d = pair(seed, n, units, scale)
    aM = np.abs(M)
    absM = (aM, float(aM.sum(axis=1).max()))
    general, fast = ErrorEllipsoid(n, 1.0, d), ErrorEllipsoid(n, 1.0, d)
    general.S, general.tr = S.copy(), float(np.trace(S)) * (1 + 4 * n * UNIT_ROUNDOFF)
    fast.S, fast.tr = S.copy(), general.tr
    general.S, general.tr = general.propagate_product(M @ S @ M.T, general.image_bound(aM), general.c_dense, rho,
                                                      absM[1])
    with _path(kernel):
        fast.step_dense(M, absM, rho)
    G, F = general.S, fast.S
    np.testing.assert_array_equal(F, F.T)                   # exactly symmetric
    r = np.sqrt(np.outer(np.diagonal(G), np.diagonal(G)))
    assert np.all(np.abs(F - G) <= RTOL * r), float(np.max(np.abs(F - G) / r))
    assert abs(fast.tr - general.tr) <= RTOL * general.tr
    assert fast.tr >= float(np.trace(F))
    # read without the symmetrisation, the solver's error from tr (>= ||S||_F): at least the general read,
    # within n^2 u of it (tr <= n lambda_max)
    general_read = math.sqrt(ErrorEllipsoid.lam_upper(fast, F.copy()))
    assert general_read <= fast.bound() <= general_read * (1.0 + n * n * UNIT_ROUNDOFF)


@pytest.mark.parametrize("kernel", PATHS)
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 64), scale=st.floats(1e-20, 1e20))
@example(seed=3, n=39, scale=1.0)
@example(seed=0, n=64, scale=1.0)
def test_fast_step_differs_from_the_general_set_within_the_allowance(kernel, seed, n, scale):
    """A rank-one ``S`` through a Gaussian map (cancellation in ``M S M'``): relative to the diagonal the
    two sets differ by far more than 1e-13 (6e-13 at n = 39, 9e-11 at n = 64), but within the rounding
    of ``Z`` and the diagonal allowances (``rho = 0``, ``alpha = 1``)."""
    rng = np.random.default_rng(seed)
    v = scale * rng.standard_normal(n)
    S, M = np.outer(v, v), rng.standard_normal((n, n))
    aM = np.abs(M)
    absM = (aM, float(aM.sum(axis=1).max()))
    general, fast = ErrorEllipsoid(n, 1.0), ErrorEllipsoid(n, 1.0)
    for ell in (general, fast):
        ell.S, ell.tr = S.copy(), float(np.trace(S)) * (1 + 4 * n * UNIT_ROUNDOFF)
    G, _ = general.propagate(M, 0.0, absM)
    with _path(kernel):
        fast.step_dense(M, absM, 0.0)
    assert allowance_ratio(fast.S, G, M, S) <= 1.0


@pytest.mark.parametrize("kernel", PATHS)
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 16), units=st.booleans(), scale=st.floats(1e-20, 1e20),
       rho=st.sampled_from([0.0, 1e-12]))
def test_fast_step_contains_the_exact_product(kernel, seed, n, units, scale, rho):
    """``S' - M S M'`` (the product in extended precision) is positive semidefinite: checked on its
    diagonal-scaled form, where the allowance is a few ``u`` of the scale."""
    M, S, d = pair(seed, n, units, scale)
    aM = np.abs(M)
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S, ell.tr = S.copy(), float(np.trace(S)) * (1 + 4 * n * UNIT_ROUNDOFF)
    with _path(kernel):
        ell.step_dense(M, (aM, float(aM.sum(axis=1).max())), rho)
    T = M.astype(LD) @ S.astype(LD) @ M.T.astype(LD)
    Dm = ell.S.astype(LD) - T
    assert np.all(np.diagonal(Dm) >= 0), float(np.min(np.diagonal(Dm)))     # sharp: fails without the allowance
    r = np.sqrt(np.abs(np.diagonal(ell.S))) + 1e-300
    X = (Dm / np.outer(r, r).astype(LD)).astype(float)
    X = 0.5 * (X + X.T)
    assert float(np.linalg.eigvalsh(X)[0]) >= -1e-12


@pytest.mark.parametrize("kernel", PATHS)
@pytest.mark.parametrize("n, m, S0, tr0, rho", [(6, 3.0, 1e307, 6e307, 1.0), (1, 1.0, 1e308, 1e308, 0.0),
                                                (6, 3.0, math.nan, math.nan, 1.0)])
def test_overflow_withdraws_without_a_warning(kernel, n, m, S0, tr0, rho):
    """A set near the largest double (or NaN): on either path the step under an error state, the set not
    finite (the kernel runs only where numpy's unguarded branch would)."""
    M = m * np.eye(n)
    ell = ErrorEllipsoid(n, 1.0)
    ell.S, ell.tr = S0 * np.eye(n), tr0
    with np.errstate(all="raise"), _path(kernel):
        ell.step_dense(M, (np.abs(M), m), rho)
    assert not ell.finite() and ell.bound() == math.inf


def test_a_step_past_the_guards_is_numpys():
    """``alpha >= 1e20`` (a residual far above the set) fails the unguarded branch's condition: the
    kernel's result is not taken, the step is numpy's to the last bit."""
    M, S, d = pair(7, 9, True, 1e-60)
    aM = np.abs(M)
    absM = (aM, float(aM.sum(axis=1).max()), aM * d[:, None])
    sets = []
    for kernel in (True, False):
        ell = ErrorEllipsoid(9, 1.0, d)
        ell.S, ell.tr = S.copy(), float(np.trace(S)) * (1 + 36 * UNIT_ROUNDOFF)
        with _path(kernel):
            ell.step_dense(M, absM, 1e-5)
        sets.append((ell.S, ell.tr))
    assert np.array_equal(sets[0][0], sets[1][0]) and sets[0][1] == sets[1][1]


@pytest.mark.parametrize("kernel", PATHS)
@pytest.mark.parametrize("rho", [math.nan, -1.0])
def test_a_residual_that_bounds_nothing_gives_a_set_that_is_not_finite(kernel, rho):
    """A NaN residual (from a NaN in the sample) is no bound on the step's error: the set is not finite,
    its bound infinite (not the set of ``rho = 0``), without a warning."""
    n = 4
    M = 0.5 * np.eye(n)
    ell = ErrorEllipsoid(n, 1.0)
    with np.errstate(all="raise"), _path(kernel):
        ell.step_dense(M, (np.abs(M), 0.5), rho)
    assert not ell.finite() and ell.bound() == math.inf


@pytest.fixture(scope="module")
def agents2():
    """camera_agents(2) (n = 12, dense maps) with its 50 Hz Kalman table for residences of 0.2 s and a
    stream of noisy samples of bodies at rest."""
    system = so.camera_agents(2)
    cycle = so.Cycle((0.2, 0.2))
    table = so.kalman_table(system, [so.design_kalman(system, cycle, 50.0)])
    sched = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(3)
    x = np.zeros(system.n)
    x[0::4], x[1::4] = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)
    stream = []
    for k in range(120):
        t = k / 50.0
        ch = sched.channel_at(t)
        stream.append((t, ch, np.asarray(system.C[ch - 1]) @ x + 1e-3 * rng.standard_normal(4)))
    return system, cycle, table, stream


@pytest.mark.parametrize("noise_max, fast_steps", [(None, 1), (0.0, 2), (1e-3, 0)])
def test_observer_publishes_the_general_paths_bounds(agents2, monkeypatch, noise_max, fast_steps):
    """Without a declared noise bound, and with the node's default ``noise.max`` 0 (a noise set with no
    noise: both sets take the fast step), the published bounds are the general path's within 1e-12;
    a noise set with noise keeps the general path (its shaped term)."""
    system, cycle, table, stream = agents2

    def run():
        obs = so.SwitchedObserver(system, table, "periodic", [cycle], noise_max=noise_max)
        out = []
        for t, ch, y in stream:
            obs.update(t, ch, y)
            env = obs.envelope()
            out.append((obs.x_hat.copy(), env.exact_bound, env.noise_bound))
        return out

    calls = []
    real = ErrorEllipsoid.step_dense

    def counted(self, *a):
        calls.append(1)
        return real(self, *a)
    monkeypatch.setattr(ErrorEllipsoid, "step_dense", counted)
    fast = run()
    table_samples = len(stream) - 20         # the first samples run the start-up's general steps
    assert fast_steps * table_samples <= len(calls) <= fast_steps * len(stream), len(calls)
    monkeypatch.setattr(KalmanMap, "dense_abs", lambda self, d=None: None)      # the general path
    general = run()
    for (xa, ba, na), (xb, bb, nb) in zip(fast, general):
        np.testing.assert_array_equal(xa, xb)       # the estimate is not touched
        assert abs(ba - bb) <= 1e-12 * bb, (ba, bb)
        assert (na is None) == (noise_max is None) == (nb is None)
        if na is not None:
            assert abs(na - nb) <= 1e-12 * nb, (na, nb)


@pytest.mark.parametrize("kernel", PATHS)
@pytest.mark.parametrize("field", ["x0", "y", "nu"])
def test_a_nan_in_a_fused_sample_withdraws_the_bound(agents2, monkeypatch, kernel, field):
    """``RoundingBound.fused_sample`` with a NaN in the estimate, the measurement or the innovation: its
    residual is NaN, the step's set not finite, the bound withdrawn (not a finite bound of ``rho = 0``)."""
    system, cycle, table, stream = agents2
    seen = []
    real = RoundingBound.fused_sample

    def kept(self, f, channel):
        seen.append((self, f, channel))
        return real(self, f, channel)
    monkeypatch.setattr(RoundingBound, "fused_sample", kept)
    obs = so.SwitchedObserver(system, table, "periodic", [cycle])
    for t, ch, y in stream[:40]:
        obs.update(t, ch, y)
    bound, f, channel = seen[-1]
    assert not bound.withdrawn and math.isfinite(bound.bounds()[0])
    bad = getattr(f, field).copy()
    bad[0] = math.nan
    with _path(kernel):
        assert real(bound, f._replace(**{field: bad}), channel)
    assert bound.withdrawn and bound.bounds()[0] == math.inf
