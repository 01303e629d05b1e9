"""frobenius_bound: ||I - K H||_F, with the rounding of fl(I - K H) and of its norm where the
Frobenius-to-2-norm slack does not cover it, bounds ||I - K H||_2 (balanced)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from _exact import bounds_spectral as _bounds_spectral
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds.kalman_map import frobenius_bound
from switchobs_core.numerics.frobenius import fro_upper


def _parts(K: np.ndarray, H: np.ndarray) -> tuple[float, float, float]:
    return fro_upper(np.eye(K.shape[0]) - K @ H), fro_upper(K), fro_upper(H)


def _exact(K: np.ndarray, H: np.ndarray) -> list[list[Fraction]]:
    """``I - K H`` in exact arithmetic (the doubles are dyadic rationals)."""
    n, p = K.shape
    Kf = [[Fraction(float(v)) for v in row] for row in K]
    Hf = [[Fraction(float(v)) for v in row] for row in H]
    return [[(1 if i == j else 0) - sum((Kf[i][k] * Hf[k][j] for k in range(p)), Fraction(0)) for j in range(n)]
            for i in range(n)]


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 6), p=st.integers(1, 4), scale=st.floats(1e-3, 1e3), seed=st.integers(0, 2**31 - 1))
def test_bounds_the_exact_spectral_norm(n: int, p: int, scale: float, seed: int) -> None:
    """The bound against ``||I - K H||_2`` of the exact product (not of ``fl(I - K H)``, whose Frobenius
    norm ``F`` bounds its own 2-norm whatever the function returns)."""
    rng = np.random.default_rng(seed)
    K, H = rng.standard_normal((n, p)) * scale, rng.standard_normal((p, n))
    F, fK, fH = _parts(K, H)
    assert _bounds_spectral(frobenius_bound(F, fK, fH, p, n), _exact(K, H))


def test_the_exact_check_rejects_the_computed_norm_where_rounding_lowers_it() -> None:
    """The check above is not vacuous: with ``n = p = 1`` (no slack) ``F`` alone is below the exact
    ``|1 - k h|`` for some gains, where the bound adds the rounding; with ``n - p >= 2`` ``F`` is below
    the exact Frobenius norm for some gains and still bounds the exact 2-norm (the slack), as returned."""
    rng = np.random.default_rng(1)
    low_alone = low_slack = 0
    for _ in range(200):
        K, H = rng.standard_normal((1, 1)), rng.standard_normal((1, 1))
        F, fK, fH = _parts(K, H)
        X = _exact(K, H)
        if not _bounds_spectral(F, X):
            low_alone += 1
            assert _bounds_spectral(frobenius_bound(F, fK, fH, 1, 1), X)
    for _ in range(60):
        K, H = rng.standard_normal((5, 2)) * 0.5, rng.standard_normal((2, 5))
        F, fK, fH = _parts(K, H)
        X = _exact(K, H)
        if Fraction(F) ** 2 < sum((v * v for row in X for v in row), Fraction(0)):
            low_slack += 1
            assert frobenius_bound(F, fK, fH, 2, 5) == F and _bounds_spectral(F, X)
    assert low_alone >= 5 and low_slack >= 1, (low_alone, low_slack)


def test_no_slack_adds_the_rounding() -> None:
    """n = 1: the Frobenius norm is the 2-norm, nothing covers fl's rounding: the bound is above F."""
    K, H = np.array([[0.3]]), np.array([[1.7]])
    F, fK, fH = _parts(K, H)
    assert frobenius_bound(F, fK, fH, 1, 1) > F


def test_slack_keeps_the_norm() -> None:
    """n = 6, p = 2, moderate gains: the slack covers the rounding, the number is F itself."""
    rng = np.random.default_rng(5)
    K, H = rng.standard_normal((6, 2)) * 0.5, rng.standard_normal((2, 6))
    F, fK, fH = _parts(K, H)
    assert frobenius_bound(F, fK, fH, 2, 6) == F
