"""The factored step's underflow allowance (:func:`~switchobs_core.bounds.kalman_map.factored_underflow`): a
set ``S`` of subnormal and near-subnormal entries through ``M = (I - K H) Phi~`` with gains ``|K|`` far above
``1 / |H|``, where the products' absolute underflow errors reach ``Z`` through ``K`` on both sides
(``||K||_inf^2``). The new set must contain ``M S M'`` computed in extended precision, by the compiled kernel
and by the numpy path alike; the rounding-aware gain of ``(1 + |K| |H|) ||Phi~||_inf`` fails here (seed 27: a
direction in which the set is below ``M S M'``)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import block_diag

from switchobs_core.bounds.kalman_map import KalmanMap
from switchobs_core.numerics import dense_kernel
from switchobs_core.numerics.propagation import ZOHEntry
from switchobs_core.numerics.rounding import ErrorEllipsoid

LD = np.longdouble
needs_ld = pytest.mark.skipif(np.finfo(LD).eps > 2.0**-60, reason="needs an extended-precision longdouble")


def _case(seed: int):
    rng = np.random.default_rng(seed)
    b = int(rng.integers(2, 5))
    blocks = int(rng.integers(max(1, 40 // b), 120 // b + 1))
    Phi = block_diag(*(np.eye(b) + 3 * rng.standard_normal((b, b)) for _ in range(blocks)))
    n = Phi.shape[0]
    p = int(rng.integers(1, 7))
    H = np.zeros((p, n))
    for r in range(p):
        H[r, rng.choice(n, size=int(rng.integers(1, 4)), replace=False)] = (
            rng.standard_normal(1) * 10.0 ** rng.integers(-5, 1))
    K = rng.standard_normal((n, p)) * 10.0 ** rng.integers(-5, 3)
    if seed % 2:
        S = np.diag(np.ldexp(1.0, rng.integers(-1074, -1000, n)).astype(float))
    else:
        x = np.ldexp(1.0, rng.integers(-537, -500, n)) * rng.choice([-1.0, 1.0], n)
        S = np.outer(x, x)          # exact: every entry a power of two >= 2^-1074
    return Phi, H, K, S


def _contains(A: np.ndarray, T: np.ndarray) -> float:
    """The least eigenvalue of ``A - T`` scaled by its diagonal (``>= 0``: ``A`` contains ``T``); -1 where a
    diagonal entry is negative."""
    D = A.astype(LD) - T
    dg = np.diagonal(D)
    if np.any(dg < 0):
        return -1.0
    r = np.sqrt(dg)
    r[r == 0] = 1
    return float(np.linalg.eigvalsh((D / np.outer(r, r)).astype(float))[0])


@needs_ld
@pytest.mark.parametrize("seed", range(60))
def test_subnormal_sets_through_large_gains_contain_the_exact_product(seed):
    Phi, H, K, S = _case(seed)
    n = Phi.shape[0]
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=None)
    M = (np.eye(n, dtype=LD) - K.astype(LD) @ H.astype(LD)) @ Phi.astype(LD)
    T = M @ S.astype(LD) @ M.T
    m = KalmanMap(e, K, H, np.eye(n))
    assert m._sp is not None        # the factored path
    ell = ErrorEllipsoid(n, 1.0)
    ell.S = S.copy()
    with dense_kernel.numpy_factored():
        Z, w, c, mn = m.sandwich(ell)
        ell.S, ell.tr = ell.propagate_product(Z, w, c, 0.0, mn)
    assert _contains(ell.S, T) >= -1e-6
    if dense_kernel.FACTORED is not None:
        ell = ErrorEllipsoid(n, 1.0)
        ell.S = S.copy()
        assert KalmanMap(e, K, H, np.eye(n)).step(ell, 0.0)
        assert _contains(ell.S, T) >= -1e-6


@pytest.mark.parametrize("rho", [float("nan"), -1.0])
def test_a_residual_that_bounds_nothing_gives_no_finite_set(rho):
    """A NaN (or negative) residual bound is ``inf`` on the factored path (kernel and numpy) as on the dense
    one: the set is not finite, so the bound is withdrawn, never the set of ``rho = 0``."""
    rng = np.random.default_rng(0)
    n, p = 44, 4
    Phi = block_diag(*(np.eye(2) + 0.3 * rng.standard_normal((2, 2)) for _ in range(22)))
    H = np.zeros((p, n))
    H[np.arange(p), [0, 5, 9, 20]] = 1.0
    K = rng.standard_normal((n, p)) * 0.5
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=None)
    with np.errstate(all="ignore"):
        ell = ErrorEllipsoid(n, 1.0)
        with dense_kernel.numpy_factored():
            Z, w, c, mn = KalmanMap(e, K, H, np.eye(n)).sandwich(ell)
            ell.S, ell.tr = ell.propagate_product(Z, w, c, rho, mn)
        assert not np.isfinite(ell.tr)
        if dense_kernel.FACTORED is not None:
            ell = ErrorEllipsoid(n, 1.0)
            assert KalmanMap(e, K, H, np.eye(n)).step(ell, rho)
            assert not np.isfinite(ell.tr)


@pytest.mark.skipif(dense_kernel.FACTORED is None, reason="the compiled kernel is not built")
def test_a_refused_call_releases_the_arrays_it_took():
    """``factored`` refusing ``H``'s rows after it took ``Phi~``'s three arrays releases them: their
    reference counts are those before the calls."""
    import sys

    from switchobs_core.bounds.kalman_map import SparseTransition

    rng = np.random.default_rng(0)
    n, p = 44, 4
    sp = SparseTransition(np.eye(n) + np.diag(rng.standard_normal(n - 1), 1))
    ip, ix, adv = sp.abs_rows
    ell = ErrorEllipsoid(n, 1.0)
    S, K = np.eye(n), rng.standard_normal((n, p))
    hj, hv = np.arange(p, dtype=np.intp), np.ones(p)
    before = [sys.getrefcount(a) for a in (ip, ix, adv)]
    for hp in (np.arange(p + 1, dtype=np.int32), np.zeros(1, np.intp)):       # a wrong type; p = 0
        for _ in range(50):
            assert dense_kernel.factored(S.copy(), S, ip, ix, adv, K, hp, hj, hv, ell._faux, 1e-6, 1.0, 1e-15,
                                         1e-15, 1e-300, 1.0) is None
    assert [sys.getrefcount(a) for a in (ip, ix, adv)] == before
