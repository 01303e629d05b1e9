"""The units of the state: a diagonal change of coordinates in which ``A`` is balanced.

A state in SI units (a position in metres beside a velocity in m/s of a 10 Hz oscillator) or a
model whose entries span 1e-6..1e6 has ``||A||_2`` set by its units, not by its dynamics: the
same system in other units has another norm, and so has every quantity computed from norms
of ``A`` (a horizon, a rank tolerance, a rounding allowance). A diagonal similarity
``A_b = D^{-1} A D`` with ``D = diag(d)`` changes the units of state ``i`` by ``d_i``; the
balancing of LAPACK's ``gebal`` (Parlett and Reinsch) picks ``d`` so that every row and column
of ``A_b`` have about the same norm, and each ``d_i`` is a power of two.

Powers of two make the change of coordinates exact in floating point: ``D^{-1} x``,
``D^{-1} M D`` and ``D S D`` are computed without rounding (barring underflow and overflow, which
:func:`balance` keeps out of reach by bounding ``d``), so an argument made in the balanced
coordinates carries over to the user's units without an allowance for the change itself.

Units do not change what :func:`balance` returns beyond powers of two: for ``A' = T A T^{-1}``
(``T`` positive diagonal) the balanced ``A'_b`` equals ``A_b`` up to a diagonal similarity by
factors in ``[1/2, 2]`` per state, so norms taken in balanced coordinates are the same in any
units within a small factor.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import matrix_balance

__all__ = ["balance", "balanced", "balanced_norm"]

#: Bound on ``|log2 d_i|``: the scalings stay far from the exponent range of doubles (a scaled
#: entry of at most 1e300 and a scaling of at most 2^200 cannot overflow together in one step).
MAX_LOG2_SCALE = 200


def balance(A: np.ndarray) -> np.ndarray:
    """``d`` (positive powers of two, shape (n,)) with ``D^{-1} A D`` balanced (module docstring);
    all ones for a matrix that is not finite or is empty."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    if n == 0 or not np.all(np.isfinite(A)):
        return np.ones(n)
    _, (d, _) = matrix_balance(A, permute=False, separate=True)
    d = np.asarray(d, dtype=float)
    if d.shape != (n,) or not np.all(np.isfinite(d) & (d > 0)):
        return np.ones(n)
    e = np.clip(np.round(np.log2(d)), -MAX_LOG2_SCALE, MAX_LOG2_SCALE)
    e -= np.round(np.median(e))         # the overall unit is the user's: the median state keeps it
    return np.ldexp(1.0, e.astype(int))


def balanced(A: np.ndarray, d: np.ndarray | None = None) -> np.ndarray:
    """``D^{-1} A D`` with ``D = diag(d)`` (default :func:`balance`'s), exact in floating point."""
    A = np.asarray(A, dtype=float)
    if d is None:
        d = balance(A)
    return (A / d[:, None]) * d[None, :]


def balanced_norm(A: np.ndarray) -> float:
    """``||D^{-1} A D||_2`` of the balanced ``A``: the size of ``A`` in units of the dynamics."""
    A = np.asarray(A, dtype=float)
    return float(np.linalg.norm(balanced(A), 2)) if A.size else 0.0
