"""frobenius_bound: ||I - K H||_F, with the rounding of fl(I - K H) and of its norm where the
Frobenius-to-2-norm slack does not cover it, bounds ||I - K H||_2 (balanced)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds.kalman_map import frobenius_bound
from switchobs_core.numerics.frobenius import fro_upper


def _parts(K: np.ndarray, H: np.ndarray) -> tuple[float, float, float]:
    return fro_upper(np.eye(K.shape[0]) - K @ H), fro_upper(K), fro_upper(H)


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 12), p=st.integers(1, 4), scale=st.floats(1e-3, 1e3), seed=st.integers(0, 2**31 - 1))
def test_bounds_the_spectral_norm(n: int, p: int, scale: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    K, H = rng.standard_normal((n, p)) * scale, rng.standard_normal((p, n))
    F, fK, fH = _parts(K, H)
    b = frobenius_bound(F, fK, fH, p, n)
    assert b >= F
    # the SVD's own error is a few u ||.||_2: the bound is above with that margin
    assert b >= np.linalg.norm(np.eye(n) - K @ H, 2) * (1.0 - 1e-13)
    if n - p >= 2:   # the slack the bound relies on: ||.||_F^2 >= ||.||_2^2 + n - p - 1
        X = np.eye(n) - K @ H
        assert np.linalg.norm(X) ** 2 >= np.linalg.norm(X, 2) ** 2 + (n - p - 1) * (1.0 - 1e-9)


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
