"""Cases shared by the tests of the dense step (``ErrorEllipsoid.step_dense``, its compiled kernel)."""

from __future__ import annotations

import math

import numpy as np

from switchobs_core.numerics.rounding import UNIT_ROUNDOFF, gamma

LD = np.longdouble


def pair(seed: int, n: int, units: bool, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(M, S, d)``: a map near a contraction, an exactly symmetric PSD ``S``, a balancing or None."""
    rng = np.random.default_rng(seed)
    M = 0.9 * np.eye(n) + 0.3 * rng.standard_normal((n, n)) / math.sqrt(n)
    X = rng.standard_normal((n, n))
    S = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    S = 0.5 * (S + S.T)
    d = np.ldexp(1.0, rng.integers(-12, 12, n)) if units else None
    return M, S, d


def allowance_ratio(A: np.ndarray, B: np.ndarray, M: np.ndarray, S: np.ndarray) -> float:
    """``max |A - B| / t`` over the entries, for two sets of one step with ``rho = 0`` (``alpha = 1``)
    rounded in other orders: ``t = 2 gamma_{2n+2} (|M| |S| |M'|) + 2 u (|A| + |B|)``, the rounding of
    ``Z = M S M'`` on either side and of the scalings, plus on the diagonal the larger of the two
    diagonal allowances (``A_ii - (M S M')_ii``, the product in extended precision). <= 1 where the two
    differ by no more than their own allowances."""
    n = M.shape[0]
    aM = np.abs(M).astype(LD)
    Zx = M.astype(LD) @ S.astype(LD) @ M.T.astype(LD)
    t = 2 * gamma(2 * n + 2) * (aM @ np.abs(S).astype(LD) @ aM.T) + 2 * UNIT_ROUNDOFF * (np.abs(A) + np.abs(B))
    dz = np.diagonal(Zx)
    t[np.diag_indices(n)] += np.maximum(np.abs(np.diagonal(A) - dz), np.abs(np.diagonal(B) - dz))
    return float(np.max(np.abs(A.astype(LD) - B.astype(LD)) / t))
