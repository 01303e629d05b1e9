r"""The error map of a Kalman sample, ``M = (I - K H) e^{A dt}``, and its ellipsoid step in factored form.

A Kalman sample (:mod:`switchobs_core.runtime.families.kalman`,
:mod:`switchobs_core.runtime.families.online`) predicts ``x^- = Phi~ x^+`` with the
computed ``Phi~ = e^{A dt}`` and corrects ``x^+ = x^- + K (y - H x^-)``; its error map is
``M = (I - K H) Phi~`` (:mod:`switchobs_core.numerics.rounding`, step 2). The rigorous bound takes
``M S M'`` every sample
(step 6): formed densely that is two n x n products, ``2 n^3`` flops, where the estimate itself
costs ``O(n^2)``.

For systems whose bodies are uncoupled (``camera_agents``: ``A`` block diagonal, ``Phi~`` has 198
nonzeros of 17 424 at n = 132) the product is taken in factors:

.. math::

    Y = \tilde\Phi S \tilde\Phi', \quad G = H Y, \quad V = Y H' - K (G H'), \quad
    Z = Y - [K \; V] [G; K']

``Z = (I - K H) Y (I - K H)' = Y - K H Y - Y H' K' + K H Y H' K'`` in exact arithmetic. ``Y`` costs
two sparse products (``4 nnz(Phi~) n`` flops), ``G`` and ``Y H'`` read only the columns of ``H``
that hold a nonzero (a channel sees a few states), and ``Z`` is one product of inner dimension
``2 p``: ``O(nnz(Phi~) n + p n^2)`` in all.

Rounding (the standard model ``|fl(A B) - A B| <= gamma_m |A| |B|``, ``m`` the inner dimension; a
sparse product or a product over a subset of columns skips exact zeros, which only shortens its
sums). Two norms of nonnegative matrices, each bounded by ``sqrt(||.||_1 ||.||_inf)`` (O(nnz) and
O(n p) to compute, rounded up): ``nu >= || |Phi~| ||_2`` (about 1 for a transition near the
identity, where ``||Phi~||_F`` is about ``sqrt(n)``) and ``kappa >= 1 + || |K| |H| ||_2``, which
bounds ``|| I + |K| |H| ||_2`` and, since ``|I - K H| <= I + |K| |H|`` entrywise,
``||I - K H||_2`` (the residual's factor too).

1. ``|Y~ - Phi~ S Phi~'| <= gamma_{2n} |Phi~| |S| |Phi~'|``: in the 2-norm at most
   ``gamma_{2n} nu^2 ||S||_2``, and through ``I - K H`` on both sides ``kappa^2`` times that.
2. The longest chain of roundings from ``Y~`` to ``Z~`` is ``G H'`` (``2n``), ``K (.)`` (``p``),
   the difference ``V`` (1), the product of inner dimension ``2p`` and the last difference (1):
   ``m = 2n + 3p + 2``. Every term of ``Z`` is one of ``Y``, ``K H Y``, ``Y H' K'``,
   ``K H Y H' K'``, so ``|Z~ - (I - K H) Y~ (I - K H)'| <= gamma_m (I + |K||H|) |Y~| (I + |H'||K'|)``,
   at most ``gamma_m kappa^2 ||Y~||_2`` in the 2-norm (the 2-norm is monotone on nonnegative
   matrices, and ``|| |Y~| ||_2 <= ...`` is taken through ``|Y~| <= (1 + gamma_{2n}) |Phi~||S||Phi~'|``).
3. With ``||S||_2 <= || |S| ||_2 <= trace S`` for the positive semidefinite ``S`` kept here
   (the same premise as step 6 of :mod:`switchobs_core.numerics.rounding`, which uses ``||S||_F <= trace S``):
   ``||Z~ - M S M'||_2 <= kappa^2 nu^2 tr (gamma_{2n} + gamma_m (1 + gamma_{2n})^2)
   <= 2.01 gamma_{2n+4p+4} kappa^2 nu^2 tr =: eta``,

and ``Z~ + eta I`` contains ``M S M'`` in the PSD order, as step 6 asks (``||S||_F <= trace S``).
The dense form is kept below :data:`SPARSE_MIN_N` states or above :data:`SPARSE_MAX_FILL` of
nonzeros (it is faster there), and it is the one :mod:`switchobs_core.numerics.rounding` documents.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg.blas import dgemm as _dgemm
from scipy.sparse import csr_array

from ..numerics.rounding import fro_norm, gamma

try:        # scipy's kernel behind ``csr_array @ dense`` (the same loop, without 30 us of checks)
    from scipy.sparse._sparsetools import csr_matvec as _csr_matvec
    from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
except ImportError:     # pragma: no cover - another scipy layout: the public product
    _csr_matvec = _csr_matvecs = None

__all__ = ["SPARSE_MIN_N", "SPARSE_MAX_FILL", "SparseTransition", "sparse_transition", "KalmanMap"]

#: Fewest states for which the factored form is used (below, dense products are as fast).
SPARSE_MIN_N = 40
#: Largest fraction of nonzeros of ``Phi~`` for which the factored form is used.
SPARSE_MAX_FILL = 0.125


class SparseTransition:
    """``Phi~`` in compressed rows: ``sandwich(S) = Phi~ S Phi~'`` and ``Phi~ @ v``."""

    __slots__ = ("n", "csr", "nu", "_ip", "_ix", "_dv")

    def __init__(self, Phi: np.ndarray) -> None:
        self.n = n = Phi.shape[0]
        self.csr = csr_array(Phi)
        self.csr.sort_indices()
        self._ip, self._ix, self._dv = self.csr.indptr, self.csr.indices, self.csr.data
        # nu >= || |Phi~| ||_2 <= sqrt(||Phi~||_1 ||Phi~||_inf) (sums of nonnegative terms, rounded up)
        a = np.abs(self._dv)
        rows = np.bincount(np.repeat(np.arange(n), np.diff(self._ip)), weights=a, minlength=n)
        cols = np.bincount(self._ix, weights=a, minlength=n)
        self.nu = math.sqrt(float(rows.max()) * float(cols.max())) * (1.0 + 2.0 * gamma(n + 2)) if n else 0.0

    def _mm(self, B: np.ndarray) -> np.ndarray:
        """``Phi~ B`` for a C-contiguous ``B`` (n x m)."""
        if _csr_matvecs is None:        # pragma: no cover
            return np.asarray(self.csr @ B)
        out = np.zeros((self.n, B.shape[1]))
        _csr_matvecs(self.n, self.n, B.shape[1], self._ip, self._ix, self._dv, B.ravel(), out.ravel())
        return out

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``Phi~ x`` (the sum over a row's nonzeros only: its rounding is within the dense one's)."""
        if _csr_matvec is None:         # pragma: no cover
            return np.asarray(self.csr @ x)
        out = np.zeros(self.n)
        _csr_matvec(self.n, self.n, self._ip, self._ix, self._dv, x, out)
        return out

    def sandwich(self, S: np.ndarray) -> np.ndarray:
        """``Phi~ S Phi~'`` as ``(Phi~ (Phi~ S)')'`` (two sparse products)."""
        X = self._mm(np.ascontiguousarray(S))
        return self._mm(np.ascontiguousarray(X.T)).T

    def sandwich_either(self, S: np.ndarray) -> np.ndarray:
        """``Phi~ S Phi~'`` or its transpose ``Phi~ S' Phi~'`` (C-ordered), whichever needs one
        copy less: ``S`` or ``S'`` is read where it lies in memory. The ellipsoid is ``sym S``, the
        same for both (:mod:`switchobs_core.numerics.rounding`, step 5)."""
        T = S if S.flags.c_contiguous else np.ascontiguousarray(S.T)     # S.T of an F-ordered S: no copy
        X = self._mm(T)                                 # Phi~ T
        return self._mm(np.ascontiguousarray(X.T))      # Phi~ T' Phi~'


def sparse_transition(entry: Any) -> SparseTransition | None:
    """The sparse form of a ZOH cache entry's ``Phi`` (kept on the entry), or None when the dense
    form is the faster one (module docstring)."""
    sp = getattr(entry, "sparse", False)
    if sp is False:
        Phi = entry.Phi
        n = Phi.shape[0]
        sp = None
        if n >= SPARSE_MIN_N and np.count_nonzero(Phi) <= SPARSE_MAX_FILL * n * n:
            sp = SparseTransition(Phi)
        entry.sparse = sp
    return sp


_COLUMNS: dict[int, tuple] = {}


def _columns(H: np.ndarray) -> tuple:
    """``(c, H[:, c])`` with ``c`` the columns of ``H`` that hold a nonzero (a channel sees a few
    states), or ``()`` when they are more than a quarter of the columns; kept per ``H`` array."""
    hit = _COLUMNS.get(id(H))
    if hit is not None and hit[0] is H:
        return hit[1]
    c = np.flatnonzero(np.any(H != 0.0, axis=0))
    out = (c, H[:, c]) if 4 * c.size <= H.shape[1] else ()
    if len(_COLUMNS) > 256:
        _COLUMNS.clear()
    _COLUMNS[id(H)] = (H, out)
    return out


class KalmanMap:
    """The error map ``M = (I - K H) Phi~`` of one Kalman sample (module docstring).

    ``KalmanMap(entry, K, H)`` with ``entry`` the ZOH cache entry of the step (``Phi~``, its
    norm, its sparse form). ``M @ X`` multiplies by ``M`` (a held map of the observer's ``Phi``);
    :meth:`sandwich` is the bound's ``M S M'`` with its rounding allowance; :attr:`kappa` bounds
    ``||I - K H||_2``.
    """

    __slots__ = ("Phi", "K", "H", "e", "_fK", "_fH", "_kappa", "_I", "_IKH", "_E", "_fE2", "_nIKH", "_sp", "_cols")

    def __init__(self, entry: Any, K: np.ndarray, H: np.ndarray, identity: np.ndarray) -> None:
        self.Phi, self.K, self.H, self.e, self._I = entry.Phi, K, H, entry, identity
        self._fK: float | None = None
        self._fH: float | None = None
        self._kappa: float | None = None
        self._IKH: np.ndarray | None = None
        self._E: np.ndarray | None = None
        self._fE2: float | None = None
        self._nIKH: float | None = None
        self._sp = sparse_transition(entry)
        self._cols: tuple | None = None

    @property
    def fK(self) -> float:
        """``||K||_F`` (for the bound only: computed at its first read)."""
        if self._fK is None:
            self._fK = fro_norm(self.K)
        return self._fK

    @property
    def fH(self) -> float:
        """``||H||_F`` (computed at its first read)."""
        if self._fH is None:
            self._fH = fro_norm(self.H)
        return self._fH

    @property
    def kappa(self) -> float:
        """``>= || I + |K| |H| ||_2 >= ||I - K H||_2``: ``1 + sqrt(||.||_1 ||.||_inf)`` of ``|K| |H|``,
        in O(n p) (module docstring)."""
        if self._kappa is None:
            K, H = self.K, self.H
            aK, aH = np.abs(K), np.abs(H)
            one = float((aK.sum(axis=0) @ aH).max()) if aH.size else 0.0
            inf = float((aK @ aH.sum(axis=1)).max()) if aK.size else 0.0
            self._kappa = 1.0 + math.sqrt(one * inf) * (1.0 + 2.0 * gamma(K.shape[0] + 2 * H.shape[0] + 2))
        return self._kappa

    def _ikh(self) -> np.ndarray:
        if self._IKH is None:
            self._IKH = self._I - self.K @ self.H
        return self._IKH

    @property
    def E(self) -> np.ndarray:
        """``M`` as a dense matrix ``(I - K H) Phi~`` (formed at its first read)."""
        if self._E is None:
            self._E = self._ikh() @ self.Phi
        return self._E

    @property
    def nIKH(self) -> float:
        """An upper bound of ``||I - K H||_2``: ``||I - K H||_F`` on the dense path, :attr:`kappa`
        on the factored one (no n x n matrix formed)."""
        if self._nIKH is None:
            self._nIKH = self.kappa if self._sp is not None else float(np.linalg.norm(self._ikh()))
        return self._nIKH

    def predict(self, x: np.ndarray) -> np.ndarray:
        """``x^- = Phi~ x`` (a new array; sparse when ``Phi~`` is)."""
        sp = self._sp
        return self.Phi @ x if sp is None else sp.matvec(x)

    @property
    def nbytes(self) -> int:
        return self.Phi.nbytes

    def __matmul__(self, other: np.ndarray) -> np.ndarray:
        if self._sp is not None and self._E is None:     # M X = Phi~ X - K (H (Phi~ X))
            PX = self._sp._mm(np.ascontiguousarray(other))
            return PX - self.K @ (self.H @ PX)
        return self.E @ other

    def sandwich(self, S: np.ndarray, tr: float, g_dense: float) -> tuple[np.ndarray, float]:
        """``(Z, eta)``: ``Z + eta I`` contains ``M S M'`` (``tr >= trace S >= ||S||_F``).

        Dense: ``Z = M S M'`` and ``eta = g_dense ||M||_F^2 tr`` (:mod:`switchobs_core.numerics.rounding`, step 6);
        factored: the module docstring's three products and its ``eta``."""
        sp = self._sp
        if sp is None:
            E = self.E
            if self._fE2 is None:
                self._fE2 = float(np.dot(E.ravel(), E.ravel()))
            return E @ S @ E.T, g_dense * self._fE2 * tr
        K, H = self.K, self.H
        Y = sp.sandwich_either(S)       # C-ordered
        cols = self._cols
        if cols is None:
            cols = self._cols = _columns(H)
        if cols:
            c, Hc = cols
            G = Hc @ Y[c]               # H Y
            YH = Y[:, c] @ Hc.T         # Y H'
            C = G[:, c] @ Hc.T          # H Y H'
        else:
            G = H @ Y
            YH = Y @ H.T
            C = G @ H.T
        # Z = Y - K G - V K' with V = Y H' - K (H Y H'): one product of inner dimension 2p
        V = YH - K @ C
        # Y <- Y - [K V] [G; K'] in one BLAS call, in place: on the F-ordered view Y' it is
        # Y' <- Y' - [G' K] [K V]' (beta = 1: no extra pass over Y)
        Zt = _dgemm(-1.0, np.concatenate((G.T, K), axis=1), np.concatenate((K.T, V.T), axis=0), 1.0, Y.T,
                    overwrite_c=True)
        Z = Zt.T
        n, p = S.shape[0], H.shape[0]
        eta = 2.01 * gamma(2 * n + 4 * p + 4) * self.kappa ** 2 * sp.nu ** 2 * tr
        return Z, eta
