"""The amortised reading of an error ellipsoid's bound (:mod:`switchobs_core.bounds.read`): every
value read bounds ``sqrt(lambda_max(sym S))`` (checked by a Cholesky factorisation of
``r^2 I - sym S`` in extended precision), most reads avoid the eigenvalue problem, and the value
stays within the documented ``sqrt((1 + tol) / (1 - tol))`` of the eigenvalue problem's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
from switchobs_core.bounds import read as read_mod
from switchobs_core.bounds.read import AnchoredBound, verified_lambda_max
from switchobs_core.numerics.rounding import ErrorEllipsoid

TOL = 0.05
LOOSE = math.sqrt((1 + TOL) / (1 - TOL)) * (1 + 1e-12)


def _psd_certificate(r: float, S: np.ndarray) -> bool:
    """``r^2 I - (S + S') / 2`` is positive semidefinite (Cholesky in long double, pivots >= 0)."""
    n = S.shape[0]
    T = -(S.astype(np.longdouble) + S.T.astype(np.longdouble)) / 2
    T[np.diag_indices(n)] += np.longdouble(r) ** 2
    for j in range(n):
        d = T[j, j] - T[j, :j] @ T[j, :j]
        if d < 0:
            return False
        T[j, j] = np.sqrt(d)
        if T[j, j] == 0:
            if np.any(np.abs(T[j + 1:, j] - T[j + 1:, :j] @ T[j, :j]) > 0):
                return False
            continue
        T[j + 1:, j] = (T[j + 1:, j] - T[j + 1:, :j] @ T[j, :j]) / T[j, j]
    return True


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 7), seed=st.integers(0, 2**31), drift=st.floats(1e-6, 0.2),
       shrink=st.floats(0.9, 1.05), asym=st.booleans())
def test_every_read_bounds_the_largest_eigenvalue(n, seed, drift, shrink, asym):
    rng = np.random.default_rng(seed)
    ell = ErrorEllipsoid(n, 1.0)
    rd = AnchoredBound(tol=TOL)
    for _ in range(40):
        M = shrink * (np.eye(n) + drift * rng.standard_normal((n, n)))
        ell.step(M, drift * 1e-3 * float(rng.random()))
        if asym:        # a float S is not exactly symmetric: the reading is of (S + S') / 2
            ell.S = ell.S + 1e-14 * float(np.abs(ell.S).max()) * rng.standard_normal((n, n))
            ell.tr = max(ell.tr, float(np.trace(ell.S))) * (1 + 1e-12)     # the kept invariant tr >= trace S
        r = rd.read(ell)
        assert _psd_certificate(r, ell.S), (r, ell.S)
        lam = float(np.linalg.eigvalsh((ell.S + ell.S.T) / 2)[-1])
        assert r <= LOOSE * math.sqrt(lam) + 1e-12 * math.sqrt(abs(float(np.trace(ell.S)))) + 1e-300


def test_observer_amortised_envelope_is_within_the_documented_factor():
    """A Kalman table at 50 Hz: the amortised bound is never below the eigenvalue problem's by
    more than its own allowance, never above it by more than the documented factor, and solves
    the eigenvalue problem on a minority of samples."""
    system = so.camera_agents(2)
    cycle = so.Cycle([1.0, 1.0])
    table = so.kalman_table(system, [so.design_kalman(system, cycle, 50.0)])
    obs = so.SwitchedObserver(system, table, "periodic", [cycle])
    rng = np.random.default_rng(3)
    x = rng.uniform(-5, 5, system.n)
    sched = so.PeriodicSchedule(cycle)
    ratios = []
    for k in range(600):
        t = k / 50.0
        ch = sched.channel_at(t)
        y = np.asarray(system.C[ch - 1]) @ x
        obs.update(t, ch, y)
        fast = obs.envelope(amortised=True).exact_bound
        exact = obs.envelope().exact_bound
        assert _psd_certificate(fast, obs._bound.ell.S)
        ratios.append(fast / exact)
    rd = obs._bound._read
    assert rd.reads == 600
    assert rd.anchors < 0.5 * rd.reads, (rd.anchors, rd.reads)
    assert min(ratios) >= 1 - 1e-9 and max(ratios) <= LOOSE, (min(ratios), max(ratios))


def test_verified_anchors_keep_the_proven_factor_on_a_dense_system():
    """n = 40, dense (test/core/_systems.py's dense40, Kalman table at 50 Hz, 20 s): every amortised
    read is a proven upper bound and within :data:`~switchobs_core.bounds.read.LOOSENESS` (1.079) of
    ``sqrt(lambda_max)`` from the eigenvalue problem; the anchors are verified candidates."""
    from _systems import dense40

    from switchobs_core.bounds.read import LOOSENESS

    system = dense40()
    cycle = so.Cycle((0.6, 0.4))
    table = so.kalman_table(system, [so.design_kalman(system, cycle, 50.0)])
    obs = so.SwitchedObserver(system, table, "periodic", [cycle])
    x = np.random.default_rng(4).uniform(-1, 1, system.n)
    F = np.asarray(so.transition(system.A, 1 / 50.0))
    sched = so.PeriodicSchedule(cycle)
    worst = 0.0
    for k in range(1000):
        t = k / 50.0
        if k:
            x = F @ x
        ch = sched.channel_at(t)
        obs.update(t, ch, np.asarray(system.C[ch - 1]) @ x)
        fast = obs.envelope(amortised=True).exact_bound
        S = obs._bound.ell.S
        lam = float(np.linalg.eigvalsh(S)[-1])
        assert fast >= math.sqrt(lam) * (1 - 1e-12)
        worst = max(worst, fast / math.sqrt(lam))
    rd = obs._bound._read
    assert worst <= LOOSENESS * (1 + 1e-9), worst
    assert rd.verified >= 0.9 * rd.anchors, (rd.verified, rd.anchors)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 39), seed=st.integers(0, 2**31), spread=st.floats(0.0, 12.0),
       scale=st.floats(-30.0, 30.0), asym=st.booleans())
def test_eigen_anchor_bounds_the_largest_eigenvalue_within_its_model(n, seed, spread, scale, asym):
    """Below 40 states the anchor's eigenvalue problem (the largest pair alone) bounds
    ``lambda_max(sym S)`` (certified in extended precision) and exceeds it by no more than its
    model, ``(2 n + 16) u ||S||_F`` twice over; its direction is a unit eigenvector (residual within
    ``n u ||S||_F``), on spectra spread over ``10^spread``, scaled by ``10^scale``."""
    from switchobs_core.bounds.read import _eigen_anchor

    rng = np.random.default_rng(seed)
    Qm, _ = np.linalg.qr(rng.standard_normal((n, n)))
    ev = 10.0 ** (scale - spread * rng.random(n))
    S = (Qm * ev) @ Qm.T
    S = (S + S.T) / 2
    if asym:
        S = S + 1e-15 * float(np.abs(S).max()) * rng.standard_normal((n, n))
    lam, v = _eigen_anchor(S)
    assert _psd_certificate(math.sqrt(lam), S), (lam, S)
    T = (S + S.T) / 2
    nS = float(np.linalg.norm(S))
    top = float(np.linalg.eigvalsh(T)[-1])
    u = np.finfo(float).eps / 2
    assert lam <= top + 2 * (2 * n + 16) * u * nS * (1 + 1e-12) + 1e-300, (lam, top)
    assert abs(float(v @ v) - 1.0) <= 1e-12
    assert float(np.linalg.norm(T @ v - float(v @ T @ v) * v)) <= 4 * n * u * nS + 1e-300


@pytest.mark.parametrize("scale", [1e-82, 1e-150])
def test_a_read_between_anchors_of_a_tiny_set_bounds_it(scale):
    """Entries of S below the square root of the smallest normal (1e-164, 1e-300): the Frobenius norms the
    read's tests use underflow (squares become subnormal or 0); what underflow can hide is added, so the
    read between anchors still bounds the set (certified in long double)."""
    n = 4
    ell = ErrorEllipsoid(n, scale)          # S = scale^2 I
    rb = AnchoredBound()
    rb.read(ell)                            # the anchor at S_a = S
    S = ell.S.copy()
    S[0, 0] *= 4.0                          # lambda_max(S) = 4 scale^2
    ell.S, ell.tr = S, float(np.trace(S))
    r = rb.read(ell)
    assert _psd_certificate(r, S), (r, math.sqrt(S[0, 0]))


def test_anchors_and_lam_upper_of_sets_below_the_normal_range_bound_them():
    """S = 1e-290 G G' (n = 2..39, then 40..44 through the Cholesky-verified read): the one-eigenpair anchor,
    the verified lambda_max and ErrorEllipsoid.lam_upper of a set not made by step_dense all bound
    lambda_max (certified in long double), though ||S||_F underflows to about 1e-290."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(2, 40))
        G = rng.standard_normal((n, n))
        S = 1e-290 * (G @ G.T)
        S = np.ascontiguousarray((S + S.T) / 2)
        lam, _ = read_mod._eigen_anchor(S)
        assert _psd_certificate(math.sqrt(lam), S), ("anchor", n, lam)
        ell = ErrorEllipsoid(n, 1.0)
        ell.S, ell.tr = S, float(np.trace(S))
        lam = ell.lam_upper()
        assert _psd_certificate(math.sqrt(lam), S), ("lam_upper", n, lam)
    for n in range(40, 45):
        G = rng.standard_normal((n, n))
        S = 1e-290 * (G @ G.T)
        S = np.ascontiguousarray((S + S.T) / 2)
        got = verified_lambda_max(S)
        if got is not None:
            assert _psd_certificate(math.sqrt(got[0]), S), ("verified", n, got[0])


@pytest.mark.parametrize("kernel", [True, False])
@pytest.mark.parametrize("n", [5, 36])
def test_reads_of_sets_near_overflow_warn_nothing(monkeypatch, kernel, n):
    """The read sets up numpy's error state itself where numpy runs (the fallbacks between anchors, the
    anchor), not around the kernel's pass: a set whose sums overflow reads ``inf`` or a finite bound that
    holds, with no warning, on the kernel's path and on numpy's."""
    import warnings

    from switchobs_core.numerics import dense_kernel

    if kernel and not dense_kernel.available():
        pytest.skip("the compiled kernel is not built")
    if not kernel:
        monkeypatch.setattr(dense_kernel, "BETWEEN", None)
        monkeypatch.setattr(dense_kernel, "ABSROWS", None)
    rng = np.random.default_rng(n)
    ell, rd = ErrorEllipsoid(n, 1.0), AnchoredBound(tol=TOL)
    X = rng.standard_normal((n, n))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for scale in (1e300, 1e305, 1e306, 1e307, 1e308):
            S = (X @ X.T) / n * scale       # entries near the largest double: their squares overflow
            ell.S, ell.tr = S, math.inf
            r = rd.read(ell)
            assert math.isinf(r) or r * r >= float(np.linalg.eigvalsh(S / scale)[-1]) * scale * (1 - 1e-9)


@pytest.mark.parametrize("kernel", [True, False])
@pytest.mark.parametrize("symmetric", [True, False])
def test_gershgorin_rows_of_a_set_near_overflow_warn_nothing(monkeypatch, kernel, symmetric):
    """A read between anchors that reaches Gershgorin's rows (the anchor's direction no longer fits): a set
    with a block of entries near the largest double reads ``inf`` or a bound that holds, with no warning,
    on the kernel's row sums and on numpy's, with the set's symmetric part given and without."""
    import warnings

    from switchobs_core.numerics import dense_kernel

    if kernel and not dense_kernel.available():
        pytest.skip("the compiled kernel is not built")
    if not kernel:
        monkeypatch.setattr(dense_kernel, "BETWEEN", None)
        monkeypatch.setattr(dense_kernel, "ABSROWS", None)
    n = 5
    Sa = np.diag([1.0, 1e-3, 1e-3, 1e-3, 1e-3])          # the anchor: its direction is e_1
    S = Sa.copy()
    S[1:, 1:] += 1e308                                   # then a set whose mass lies off that direction
    ell, rd = ErrorEllipsoid(n, 1.0), AnchoredBound(tol=TOL)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for X in (Sa, S):
            ell.S = X.copy()
            if symmetric:
                ell.symmetric = ell.S
            ell.tr = math.inf
            r = rd.read(ell)
    assert r * r == math.inf       # the block's largest eigenvalue, 4e308, is above the largest double
