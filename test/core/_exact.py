"""Exact checks in rationals for the tests (every double is a dyadic rational)."""

from __future__ import annotations

from fractions import Fraction


def psd(M: list[list[Fraction]]) -> bool:
    """Whether the symmetric rational matrix ``M`` is positive semidefinite (exact symmetric elimination:
    every pivot >= 0, a zero pivot with a zero row)."""
    M = [row[:] for row in M]
    n = len(M)
    for k in range(n):
        piv = M[k][k]
        if piv < 0 or (piv == 0 and any(M[k][j] != 0 for j in range(k + 1, n))):
            return False
        if piv == 0:
            continue
        for i in range(k + 1, n):
            f = M[i][k] / piv
            for j in range(k + 1, n):
                M[i][j] -= f * M[k][j]
    return True


def bounds_spectral(b: float, X: list[list[Fraction]]) -> bool:
    """``b >= ||X||_2`` exactly (``X`` rows of rationals, any shape): ``b^2 I - X' X`` is positive
    semidefinite."""
    m, q = len(X), len(X[0])
    b2 = Fraction(b) ** 2
    return psd([[(b2 if i == j else 0) - sum((X[k][i] * X[k][j] for k in range(m)), Fraction(0))
                 for j in range(q)] for i in range(q)])
