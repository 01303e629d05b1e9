"""Norms as upper bounds with what underflow hides from them.

A computed ``||X||_F = sqrt(fl(v . v))`` (:func:`~switchobs_core.numerics.rounding.fro_norm`) is below
the true one by its relative rounding and, where entries fall below ``~1e-154``, by what their squares'
underflow loses: each square under the normal range loses up to ``eta / 2`` (``eta`` the smallest
subnormal, :data:`~switchobs_core.numerics.rounding.UNDERFLOW`), so ``fl(v . v)`` of ``m`` entries is
below the rounded true sum by at most ``m eta`` and, with ``sqrt(a + b) <= sqrt(a) + sqrt(b)``, the norm
by at most ``sqrt(m eta)``. The functions here add that term; the relative rounding stays the caller's
(a ``(1 + gamma)`` factor where the bound is formed).

Where the computed sum is large enough the term is not needed (:func:`sum_slack`). Let ``s`` be the
computed sum of the ``m`` squares ``x_i^2``, round to nearest, in any order, fused or not (OpenBLAS
on an FMA machine forms ``fl(x_i x_i + acc)`` in one step). Each step, a square, an addition or a
fused multiply-add, errs by at most ``u`` relative or ``eta / 2`` absolute (``eta`` the smallest
subnormal; the absolute part only where its result falls under ``2^-1022``,
:data:`~switchobs_core.numerics.rounding.NORMAL`, and a plain addition of doubles is exact there): at
most ``m`` steps carry an absolute part (one per square, fused or not), and each ``x_i^2`` passes
through at most ``m`` roundings. Hence ``T = sum x_i^2 <= (s + m eta / 2) (1 - u)^-m``. If ``s >= m
2^-1022`` then ``m eta / 2 = u m 2^-1022 <= u s`` and, as ``(1 + u) (1 - u)^-m <= (1 - u)^-(m+1)``,
``T <= s (1 - u)^-(m+1) <= s (1 + gamma_{m+1})``; with ``fl(sqrt(s)) >= sqrt(s) (1 - u)``,
``sqrt(T) <= fl(sqrt(s)) (1 + gamma_{m+1})^(1/2) / (1 - u) <= fl(sqrt(s)) (1 + gamma_{m+2})``: the
factor the callers apply without underflow (``(1 + gamma_{m+2})``, its own product rounded up) covers
it, and a published number is the one computed without the term.
"""

from __future__ import annotations

import math

import numpy as np

from .rounding import NORMAL, UNDERFLOW, fro_norm

__all__ = ["SQRT_ETA", "fro_upper", "sum_slack", "underflow_slack"]

#: ``sqrt(eta)``: the norm of ``m`` entries hides at most ``sqrt(m) SQRT_ETA`` under the normal range.
SQRT_ETA = math.sqrt(UNDERFLOW)


def underflow_slack(m: float) -> float:
    """``sqrt(m eta)``: what underflow can hide from a computed 2-norm / Frobenius norm of ``m`` entries
    (or from a square root of any sum whose underflows lose at most ``m eta`` in all)."""
    return math.sqrt(m) * SQRT_ETA


def sum_slack(s: float, m: float) -> float:
    """What underflow can hide from ``sqrt(s)``, ``s`` a computed sum of ``m`` squares: 0 when ``s >= m
    2^-1022`` (the factor ``(1 + gamma_{m+2})`` the caller applies covers it: module docstring), else
    :func:`underflow_slack`."""
    return 0.0 if s >= m * NORMAL else underflow_slack(m)


def fro_upper(X: np.ndarray) -> float:
    """``||X||_F`` computed (:func:`~switchobs_core.numerics.rounding.fro_norm`) plus what underflow can
    hide from it, ``sqrt(X.size eta)``: an upper bound up to the relative rounding the callers allow for
    (a vector's Euclidean norm is its Frobenius norm)."""
    return fro_norm(X) + math.sqrt(X.size) * SQRT_ETA
