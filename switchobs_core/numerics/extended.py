"""Extended-precision matrix products at the speed of double-precision BLAS, and ``e^{M dt}`` with them.

``np.longdouble`` (a 64-bit significand on x86, unit roundoff ``u_x = 2^-64``) is the arithmetic of
the plant's truth, the state the rounding-aware bounds are checked against
(:class:`~switchobs_core.sim.plant.Plant` with ``extended=True``). numpy multiplies ``longdouble``
matrices with a plain loop, about 100x slower than BLAS in double (11 ms against 0.1 ms at
n = 132), and a scaling and squaring takes 5-20 products.

:func:`ext_matmul` splits each factor once (Ozaki's error-free splitting): the left one by rows,
``A = diag(a) (I + R)``, the right one by columns, ``B = (J + S) diag(b)``, with ``a``, ``b`` powers
of two, ``I``, ``J`` integers with ``|I|, |J| <= 2^beta`` and ``|R|, |S| <= 1/2``, for
``beta = floor((53 - ceil(log2 k)) / 2)`` and ``k`` the inner dimension. Every step of the split
is exact (a power-of-two scaling, a rounding to an integer, a subtraction exact by Sterbenz's
lemma). Then

* ``I J`` is computed *exactly* by double-precision BLAS: every dot product sums ``k`` integers of
  magnitude at most ``2^{2 beta}``, so all partial sums are integers below ``2^53``, in any order
  and with or without fused multiply-adds;
* the rest, ``I S + R (J + S)``, is one double-precision product with inner dimension ``2k``, of
  terms ``2^beta`` times smaller than those of ``I J``: its rounding (``gamma_{2k}`` of
  ``|I| |S| + |R| |J + S|``, plus ``u`` for rounding ``R``, ``S`` and ``J + S`` to double) is at most
  ``(2k + 3) u 2^{-beta} k`` times ``max_row |A| max_col |B|`` per entry (``u = 2^-53``),
* and the two are added in extended precision and scaled back exactly.

For k = 132 (``beta = 22``) that is below ``0.13 k u_x max|A_i.| max|B_.j|``, under the classical
bound ``k u_x |A| |B|`` of numpy's own ``longdouble`` product wherever rows and columns are balanced;
:func:`expm_extended` balances its argument first (a diagonal similarity by powers of two, exact),
so its products are. Cost: 3 k n^2 multiply-adds in BLAS and O(n^2) in extended precision.
Tests check both against a 50-digit decimal reference.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .scaling import balance

__all__ = ["ext_matmul", "expm_extended"]

_LD = np.longdouble
#: Largest 1-norm of the scaled argument of :func:`expm_extended`'s Taylor series.
_THETA = 0.5


def _beta(k: int) -> int:
    """Bits of the integer part so that a length-``k`` dot product of integer parts is exact in double."""
    return max(1, (53 - max(1, math.ceil(math.log2(max(k, 2))))) // 2)


class _Split(NamedTuple):
    """``M = scale * (I + R)`` (module docstring): ``I`` and ``R`` in double, ``I`` exact,
    ``full = fl(I + R)`` (the right factor's ``J + S``), ``scale`` per row or per column."""

    I: np.ndarray
    R: np.ndarray
    full: np.ndarray
    scale: np.ndarray


def _split(M: np.ndarray, axis: int, beta: int) -> _Split:
    """Split ``M`` (extended) per row (``axis=1``) or per column (``axis=0``)."""
    mu = np.abs(M).max(axis=axis, keepdims=True)
    _, e = np.frexp(mu)                             # mu <= 2^e (e = 0 for a zero row)
    scale = np.ldexp(_LD(1), (e - beta).astype(np.int32))
    X = M / scale                                   # exact: a power of two; |X| <= 2^beta
    I = np.rint(X)                                  # exact
    X -= I                                          # exact, |X| <= 1/2
    R = X.astype(float)
    I = I.astype(float)                             # exact: an integer of at most beta + 1 bits
    return _Split(I, R, I + R, scale)


def _product(a: _Split, b: _Split) -> np.ndarray:
    """``A B`` from the splits of ``A`` (by rows) and ``B`` (by columns)."""
    P = a.I @ b.I                                   # exact (module docstring)
    Q = np.hstack((a.I, a.R)) @ np.vstack((b.R, b.full))
    C = P.astype(_LD)
    C += Q.astype(_LD)
    C *= a.scale * b.scale                          # exact: powers of two
    return C


def ext_matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` in extended precision (``np.longdouble`` in and out) by double-precision BLAS
    (module docstring); anything but finite matrices takes numpy's own ``longdouble`` product."""
    A = np.asarray(A, dtype=_LD)
    B = np.asarray(B, dtype=_LD)
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[0] or A.size == 0 or B.size == 0 \
            or not (np.isfinite(A).all() and np.isfinite(B).all()):
        return A @ B
    beta = _beta(A.shape[1])
    return _product(_split(A, 1, beta), _split(B, 0, beta))


def expm_extended(M: np.ndarray, dt: float) -> np.ndarray:
    """``e^{M dt}`` in extended precision (``np.longdouble``): in the coordinates that balance ``M``
    (:func:`~switchobs_core.numerics.scaling.balance`, exact), scaling and squaring of a Taylor
    series summed to below the extended precision's unit roundoff, every product by
    :func:`ext_matmul`'s splitting (a reference for tests and the extended-precision plant; the
    bound itself never uses it)."""
    Md = np.asarray(M, dtype=float)
    n = Md.shape[0]
    d = balance(Md) if n else np.ones(0)
    dl = np.asarray(d, dtype=_LD)
    X = (np.asarray(M, dtype=_LD) * _LD(dt)) / dl[:, None] * dl[None, :]      # exact similarity
    nrm = float(np.abs(X).sum(axis=0).max()) if X.size else 0.0
    if not math.isfinite(nrm):
        return np.full(X.shape, np.nan, dtype=_LD)
    s = max(0, math.ceil(math.log2(nrm / _THETA))) if nrm > _THETA else 0
    X = X / _LD(2.0**s)
    E = np.eye(n, dtype=_LD)
    if n == 0:
        return E
    beta = _beta(n)
    x = _split(X, 0, beta)                          # the right factor of every Taylor product
    T = E.copy()
    tiny = float(np.finfo(_LD).eps) / 16
    for k in range(1, 40):
        T = _product(_split(T, 1, beta), x) / _LD(k)
        E += T
        if float(np.abs(T).max()) <= tiny * float(np.abs(E).max()):
            break
    for _ in range(s):
        E = _product(_split(E, 1, beta), _split(E, 0, beta))
    return E * (dl[:, None] / dl[None, :])           # back to the given coordinates, exact
