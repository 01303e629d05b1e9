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

Units. ``gebal`` balances each strongly connected part of ``A``'s graph, but the relative unit of
two parts that only one of them couples into (a Jordan block of two oscillators, the uncoupled
bodies of a camera scenario) is free, and it returns a different one in other units (measured:
a factor 1024 between the two oscillators of test/core/_systems.py's ``oscillator_si`` when its
velocities are in km/s). With the outputs ``C`` given, :func:`balance` pins those units too: ``x
= log d`` minimises the convex

.. math::

    F(x) = \\sum_{i \ne j} |A_{ij}| e^{x_j - x_i}
         + w \\sum_{C_{oi} \ne 0} \big(|C_{oi}| e^{x_i} + e^{-x_i} / |C_{oi}|\big)

(the sum of the balanced ``|A_b|``, Osborne's objective, plus a pull of every measured state
to the units of its outputs; ``w`` is the ``A`` part at ``gebal``'s point per nonzero of
``C``), by cyclic coordinate descent (each step the exact minimiser in one ``x_i``). For
``A' = T A T^{-1}``, ``C' = C T^{-1}`` (``T`` positive diagonal) ``F'(x + log T) = F(x)``, so the
minimiser moves by ``log T`` exactly and ``D'^{-1} A' D' = D^{-1} A D``: the balanced
coordinates are the same in any units of the state, up to the rounding of ``d`` to powers of two
(a factor in ``[1/2, 2]`` per state) and of the descent's stopping point.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import get_lapack_funcs

__all__ = ["balance", "balanced", "balanced_norm"]

#: Bound on ``|log2 d_i|``: the scalings stay far from the exponent range of doubles (a scaled
#: entry of at most 1e300 and a scaling of at most 2^200 cannot overflow together in one step).
MAX_LOG2_SCALE = 200


def balance(A: np.ndarray, C: np.ndarray | None = None) -> np.ndarray:
    """``d`` (positive powers of two, shape (n,)) with ``D^{-1} A D`` balanced (module docstring):
    ``gebal``'s alone, or with the stacked outputs ``C`` the minimiser of ``F``; all ones for a
    matrix that is not finite or is empty."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    if n == 0 or not np.all(np.isfinite(A)):
        return np.ones(n)
    d = _gebal_scaling(A)
    if d.shape != (n,) or not np.all(np.isfinite(d) & (d > 0)):
        d = np.ones(n)
    x = np.log(d)
    if C is not None:
        C = np.asarray(C, dtype=float).reshape(-1, n)
        if np.all(np.isfinite(C)):
            x = _pinned(np.abs(A), np.abs(C), x)
    e = np.clip(np.round(x / math.log(2.0)), -MAX_LOG2_SCALE, MAX_LOG2_SCALE)
    e -= np.round(_median(e))           # the overall unit is the user's: the median state keeps it
    return np.ldexp(1.0, e.astype(int))


def _median(e: np.ndarray) -> float:
    """``np.median(e)`` of a 1-d array (the middle value, or the mean of the two middle ones; NaN if any is
    NaN), without numpy's check for a masked array (which imports ``numpy.ma``)."""
    s = np.sort(e)
    if s.size == 0 or np.isnan(s[-1]):
        return float("nan")
    k = s.size // 2
    # ``+ 0.0``: a zero median is +0.0, as numpy's (its mean starts from +0.0).
    return (float(s[k]) if s.size % 2 else float((s[k - 1] + s[k]) / 2)) + 0.0


def _gebal_scaling(A: np.ndarray) -> np.ndarray:
    """The scaling of LAPACK's ``gebal`` (job ``'S'``: scale, no permutation) of a finite square ``A``:
    what ``scipy.linalg.matrix_balance(A, permute=False, separate=True)`` returns as its scaling, from the
    same routine with the same arguments, without the wrapper's input checks (which import
    ``numpy.ma`` to ask whether ``A`` is masked: 9 ms of a node's start)."""
    gebal = get_lapack_funcs("gebal", (A,))
    _, lo, hi, ps, info = gebal(A, scale=1, permute=0, overwrite_a=0)
    if info < 0:
        return np.ones(A.shape[0])
    d = np.ones(A.shape[0])
    d[lo:hi + 1] = ps[lo:hi + 1]
    return d


def _pinned(aA: np.ndarray, aC: np.ndarray, x: np.ndarray, sweeps: int = 200, tol: float = 1e-3) -> np.ndarray:
    """The minimiser of the module docstring's ``F`` by cyclic coordinate descent from ``x``."""
    n = aA.shape[0]
    M = aA.copy()
    np.fill_diagonal(M, 0.0)
    nz = aC > 0
    if not nz.any():
        return x
    ex = np.exp(x)
    fa = float(((M * ex[None, :]) / ex[:, None]).sum())
    w = (fa if fa > 0 else 1.0) / int(nz.sum())
    cu = w * aC.sum(axis=0)                                     # coefficient of e^{x_i}
    cd = w * np.where(nz, 1.0 / np.where(nz, aC, 1.0), 0.0).sum(axis=0)     # of e^{-x_i}
    for _ in range(sweeps):
        moved = 0.0
        for i in range(n):
            ex = np.exp(x)
            a = float(M[i] @ ex) + cd[i]                         # e^{-x_i} (row i of A_b)
            b = float(M[:, i] @ (1.0 / ex)) + cu[i]              # e^{x_i} (column i)
            if a > 0.0 and b > 0.0:
                xi = 0.5 * math.log(a / b)
                moved = max(moved, abs(xi - x[i]))
                x[i] = xi
        if moved < tol:
            break
    return x


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
