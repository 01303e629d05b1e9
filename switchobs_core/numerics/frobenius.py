"""Norms as upper bounds with what underflow hides from them.

A computed ``||X||_F = sqrt(fl(v . v))`` (:func:`~switchobs_core.numerics.rounding.fro_norm`) is below
the true one by its relative rounding and, where entries fall below ``~1e-154``, by what their squares'
underflow loses: each square under the normal range loses up to ``eta / 2`` (``eta`` the smallest
subnormal, :data:`~switchobs_core.numerics.rounding.UNDERFLOW`), so ``fl(v . v)`` of ``m`` entries is
below the rounded true sum by at most ``m eta`` and, with ``sqrt(a + b) <= sqrt(a) + sqrt(b)``, the norm
by at most ``sqrt(m eta)``. The functions here add that term; the relative rounding stays the caller's
(a ``(1 + gamma)`` factor where the bound is formed). In normal ranges the term is ``~1e-160`` and a
published number does not change.
"""

from __future__ import annotations

import math

import numpy as np

from .rounding import UNDERFLOW, fro_norm

__all__ = ["SQRT_ETA", "fro_upper", "underflow_slack"]

#: ``sqrt(eta)``: the norm of ``m`` entries hides at most ``sqrt(m) SQRT_ETA`` under the normal range.
SQRT_ETA = math.sqrt(UNDERFLOW)


def underflow_slack(m: float) -> float:
    """``sqrt(m eta)``: what underflow can hide from a computed 2-norm / Frobenius norm of ``m`` entries
    (or from a square root of any sum whose underflows lose at most ``m eta`` in all)."""
    return math.sqrt(m) * SQRT_ETA


def fro_upper(X: np.ndarray) -> float:
    """``||X||_F`` computed (:func:`~switchobs_core.numerics.rounding.fro_norm`) plus what underflow can
    hide from it, ``sqrt(X.size eta)``: an upper bound up to the relative rounding the callers allow for
    (a vector's Euclidean norm is its Frobenius norm)."""
    return fro_norm(X) + math.sqrt(X.size) * SQRT_ETA
