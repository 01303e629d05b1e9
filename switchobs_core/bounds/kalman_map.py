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

Rounding (the standard model ``|fl(A B) - A B| <= gamma_m |A| |B|``, ``m`` the number of terms of
the longest sum: a sparse product, or a product over the columns a row holds, skips exact zeros,
and a term ``0 * x`` or a sum ``s + 0`` is exact, so only the nonzero terms count). ``S`` is exactly
symmetric and positive semidefinite (:mod:`switchobs_core.numerics.rounding`, step 6), so
``|S| <= s s'`` with ``s = sqrt(diag S)``; write ``y = |Phi~| s``, ``J = I + |K| |H|``
(``|I - K H| <= J`` entrywise), ``k`` the most nonzeros in a row of ``Phi~``
(:attr:`SparseTransition.k`) and ``h`` the most nonzeros in a row of ``H``.

1. ``X = Phi~ S`` sums at most ``k`` terms per entry: ``|X~ - Phi~ S| <= gamma_k |Phi~| |S|``, and
   ``Y = Phi~ X'`` again: ``|Y~ - Phi~ S Phi~'| <= (gamma_k + gamma_k (1 + gamma_k)) |Phi~| |S| |Phi~'|
   <= gamma_{2k} y y'`` (``2 gamma_k + gamma_k^2 <= gamma_{2k}``), and through ``I - K H`` on both sides
   at most ``gamma_{2k} (J y) (J y)'``.
2. The longest chain of roundings from ``Y~`` to ``Z~`` is ``G H'`` (``2h``: ``G = H Y`` and
   ``G H'`` each sum a row of ``H``'s nonzeros), ``K (.)`` (``p``), the difference ``V`` (1), the
   product of inner dimension ``2p`` and the last difference (1): ``m = 2h + 3p + 2``. Every term of
   ``Z`` is one of ``Y``, ``K H Y``, ``Y H' K'``, ``K H Y H' K'``, so
   ``|Z~ - (I - K H) Y~ (I - K H)'| <= gamma_m J |Y~| J' <= gamma_m (1 + gamma_{2k}) (J y) (J y)'``.
3. So ``|Z~ - M S M'| <= c w w'`` entrywise with ``w = J y = y + |K| (|H| y)`` (``O(nnz(Phi~) + n p)``,
   never an ``n x n`` product) and ``c = gamma_{2k} + gamma_m (1 + gamma_{2k})`` (rounded up): the form
   :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.propagate_product` turns into an
   allowance in the shape of ``w`` (in balanced units, the same in any units of the state). For
   ``camera_agents(32)`` (``n = 132``, ``k = 2``, ``h = 1``, ``p = 4``): ``c = gamma_4 +
   gamma_16 (1 + gamma_4) = 2.2e-15``, where counting every sum as ``n`` long gives
   ``2.01 gamma_{2n+4p+4} = 6.3e-14``.

Where the compiled kernel is built (:mod:`switchobs_core.numerics.dense_kernel`), ``Phi~ S Phi~'`` is its
:func:`~switchobs_core.numerics.dense_kernel.sandwich` (scipy's doubles) and the rest of a sample's step, ``Z``,
``w`` and the assembly of :mod:`switchobs_core.numerics.rounding` (steps 5-8), one call of
:func:`~switchobs_core.numerics.dense_kernel.factored` (:meth:`KalmanMap.step`): the same products, their sums
in index order. The counts above hold for any order of each sum (the standard model's ``gamma_m`` bounds a sum
of ``m`` terms however it is ordered), so both paths carry the same ``c`` and ``w``; their sets differ in the
last bits.

The residual's factor ``||I - K H||`` is taken in the balanced coordinates of the entry's
``scale`` (``kappa >= 1 + || |D^-1 K| |H D| ||_2``, by ``sqrt(||.||_1 ||.||_inf)``), like every
norm of the rigorous bound. The dense form is kept below :data:`SPARSE_MIN_N` states or above
:data:`SPARSE_MAX_FILL` of nonzeros (it is faster there); its map ``E~ = fl(fl(I - K H) Phi~)``
differs from ``(I - K H) Phi~`` by at most :attr:`KalmanMap.emap` (balanced 2-norm), which joins
the residual.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg.blas import dgemm as _dgemm
from scipy.sparse import csr_array

from ..numerics import dense_kernel
from ..numerics.csr import csr_matmat, csr_matvec
from ..numerics.expm_bound import nu
from ..numerics.frobenius import fro_upper
from ..numerics.rounding import UNDERFLOW, UNIT_ROUNDOFF, gamma

__all__ = ["SPARSE_MIN_N", "SPARSE_MAX_FILL", "SparseTransition", "sparse_form", "sparse_map", "sparse_transition",
           "KalmanMap", "frobenius_bound", "open_loop_product"]

#: Fewest states for which the factored form is used (below, dense products are as fast).
SPARSE_MIN_N = 40
#: Largest fraction of nonzeros of ``Phi~`` for which the factored form is used.
SPARSE_MAX_FILL = 0.125


class SparseTransition:
    """``Phi~`` in compressed rows: ``sandwich(S) = Phi~ S Phi~'`` and ``Phi~ @ v``; :attr:`k` the most
    nonzeros in a row (the terms of the longest sum a product takes), :attr:`c` the allowance of
    :meth:`sandwich`: ``|fl(Phi~ S Phi~') - Phi~ S Phi~'| <= c y y'`` entrywise for a PSD ``S``,
    ``y = |Phi~| sqrt(diag S)`` (module docstring, step 1: ``c = gamma_{2k}``)."""

    __slots__ = ("n", "csr", "nu", "inf_norm", "k", "c", "_ip", "_ix", "_dv", "_adv", "abs_rows")

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
        self.inf_norm = float(rows.max()) * (1.0 + 2.0 * gamma(n + 2)) if n else 0.0
        self.k = int(np.diff(self._ip).max()) if n else 0
        self.c = gamma(2 * self.k)
        self._adv = a
        #: ``|Phi~|`` as ``(indptr, indices, data)``, the indices as ``np.intp``: the compiled kernel's
        #: (:mod:`~switchobs_core.numerics.dense_kernel`).
        self.abs_rows = (self._ip.astype(np.intp), self._ix.astype(np.intp), a)

    def abs_matvec(self, x: np.ndarray) -> np.ndarray:
        """``|Phi~| x`` (for ``x >= 0``: the factored step's ``y``)."""
        return csr_matvec(self._ip, self._ix, self._adv, (self.n, self.n), x)

    def matmat(self, B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``Phi~ B`` for a dense ``B`` (n x m), in ``out`` if given
        (:func:`~switchobs_core.numerics.csr.csr_matmat`)."""
        return csr_matmat(self._ip, self._ix, self._dv, (self.n, self.n), B, out)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``Phi~ x`` (the sum over a row's nonzeros only: its rounding is within the dense one's)."""
        return csr_matvec(self._ip, self._ix, self._dv, (self.n, self.n), x)

    def sandwich(self, S: np.ndarray) -> np.ndarray:
        """``Phi~ S Phi~'`` as ``(Phi~ (Phi~ S)')'`` (two sparse products)."""
        X = self.matmat(S)
        return self.matmat(X.T).T

    def sandwich_either(self, S: np.ndarray, scratch: np.ndarray | None = None) -> np.ndarray:
        """``Phi~ S Phi~'`` or its transpose ``Phi~ S' Phi~'`` (C-ordered, a new array), whichever needs
        one copy less: ``S`` or ``S'`` is read where it lies in memory. The ellipsoid is ``sym S``, the
        same for both (:mod:`switchobs_core.numerics.rounding`, step 5). ``scratch``: a C-ordered n x n
        array (not ``S``) for ``(Phi~ T)'``; the result is then written over ``Phi~ T`` (two n x n arrays
        touched instead of three; the same doubles). By the compiled kernel where it is built
        (:func:`~switchobs_core.numerics.dense_kernel.sandwich`: the same doubles), else scipy's products."""
        T = S if S.flags.c_contiguous else np.ascontiguousarray(S.T)     # S.T of an F-ordered S: no copy
        if dense_kernel.SANDWICH is not None:       # the same doubles in one call
            use = scratch is not None and scratch.shape == T.shape and scratch.flags.c_contiguous and scratch is not T
            Y = dense_kernel.sandwich(*self.abs_rows[:2], self._dv, T, scratch if use else np.empty(T.shape))
            if Y is not None:
                return Y
        X = self.matmat(T)                                 # Phi~ T
        if scratch is None or scratch.shape != X.shape or not scratch.flags.c_contiguous or scratch is T:
            return self.matmat(X.T)      # Phi~ T' Phi~'
        np.copyto(scratch, X.T)
        return self.matmat(scratch, X)


def sparse_transition(entry: Any) -> SparseTransition | None:
    """The sparse form of a ZOH cache entry's ``Phi`` (kept on the entry), or None when the dense
    form is the faster one (module docstring)."""
    sp = getattr(entry, "sparse", False)
    if sp is False:
        sp = entry.sparse = sparse_form(entry.Phi)
    return sp


def sparse_form(M: np.ndarray) -> SparseTransition | None:
    """``M`` in compressed rows where its products are the cheaper that way (at least
    :data:`SPARSE_MIN_N` states and at most :data:`SPARSE_MAX_FILL` of nonzeros), else None: the
    one rule for every sparse form of a map."""
    n = M.shape[0]
    return SparseTransition(M) if n >= SPARSE_MIN_N and np.count_nonzero(M) <= SPARSE_MAX_FILL * n * n else None


def sparse_map(entry: Any) -> SparseTransition | None:
    """The sparse form of a ZOH cache entry's error map ``E`` (``Phi~ - Gamma L C`` with a held
    innovation, else ``Phi~``; kept on the entry), or None when the dense form is the faster one:
    chosen as :func:`sparse_transition` chooses, by the size and the count of nonzeros of ``E``."""
    E = entry.E
    if E is entry.Phi:
        return sparse_transition(entry)
    sp = getattr(entry, "sparse_E", False)
    if sp is False:
        sp = entry.sparse_E = sparse_form(E)
    return sp


def open_loop_product(ell: Any, sp: SparseTransition) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``(Z, w, c, mn)`` of the ellipsoid's step through a sparse map ``E`` (compressed rows,
    :class:`SparseTransition`: an open-loop ``Phi~``, or the error map ``Phi~ - Gamma L C`` of a held
    innovation): ``Z = E S E'`` in two sparse products, with ``|Z - E S E'| <= c w w'`` entrywise for
    ``w >= |E| s`` and ``c = gamma_{2k}``, ``k`` the most nonzeros in a row of ``E`` (each sum of the two
    products has at most ``k`` terms: the module docstring's step 1; the dense product's is ``gamma_{2n+2}``), and
    ``mn >= ||E||_inf``: what :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.propagate_product`
    takes. ``O(nnz(E) n)`` instead of two dense products."""
    return sp.sandwich_either(ell.S, ell.scratch()), ell.image_bound(sp.abs_matvec), sp.c, sp.inf_norm


_COLUMNS: dict[int, tuple] = {}
_ROWS: dict[int, tuple] = {}


def _rows(H: np.ndarray) -> tuple[tuple, int]:
    """``((indptr, indices, data), h)``: ``H`` in compressed rows (``np.intp`` indices, each row's columns in
    ascending order) and ``h`` the most nonzeros in a row, for the compiled kernel; kept per ``H`` array."""
    hit = _ROWS.get(id(H))
    if hit is not None and hit[0] is H:
        return hit[1]
    r, c = np.nonzero(H)        # row by row, columns ascending
    ip = np.zeros(H.shape[0] + 1, dtype=np.intp)
    np.cumsum(np.bincount(r, minlength=H.shape[0]), out=ip[1:])
    out = ((ip, c.astype(np.intp), np.ascontiguousarray(H[r, c], dtype=float)),
           int(np.diff(ip).max()) if H.shape[0] else 0)
    if len(_ROWS) > 256:
        _ROWS.clear()
    _ROWS[id(H)] = (H, out)
    return out


def _allowance(sp: SparseTransition, h: int, p: int) -> float:
    """``c`` of the module docstring's step 3 (rounded up) for ``Phi~``'s sparse form ``sp``, ``h`` the most
    nonzeros in a row of ``H`` and ``p`` its rows: ``gamma_{2k} + gamma_m (1 + gamma_{2k})``, ``m = 2h + 3p + 2``."""
    g1, gm = sp.c, gamma(2 * h + 3 * p + 2)         # steps 1 and 2
    return (g1 + gm * (1.0 + g1)) * (1.0 + 4.0 * gamma(1))


def factored_underflow(sp: SparseTransition, K: np.ndarray, H: np.ndarray, h: int) -> float:
    """The factored step's underflow gain ``mn``: the plan's underflow allowance (rounding.py, step 8) holds
    ``(n + 4) eta (2 + mn)`` per entry of ``Z``, and the products' absolute underflow errors reach ``Z`` at most
    ``(k + h + 2p) (1 + ||Phi~||_inf) (1 + ||K||_inf)^2 (1 + ||H||_inf)^2 eta`` (``k`` and ``h`` the most
    nonzeros in a row of ``Phi~`` and ``H``): each product ``a b`` errs by ``eta`` absolute, a sum by nothing
    more, so ``Y`` by ``k (1 + ||Phi~||_inf) eta``, ``G = H Y`` and ``Y H'`` by ``||H||_inf`` times that plus
    ``h eta``, ``C = G H'`` again, ``K C`` by ``||K||_inf`` times ``C``'s plus ``p eta``, and ``Z = Y - K G - V K'``
    carries ``C``'s through ``K`` on both sides: hence ``||K||_inf^2``. Rounded up."""
    p, n = H.shape
    nK = float(np.abs(K).sum(axis=1).max()) if K.size else 0.0
    nH = float(np.abs(H).sum(axis=1).max()) if H.size else 0.0
    gain = (sp.k + h + 2 * p) * (1.0 + sp.inf_norm) * (1.0 + nK) ** 2 * (1.0 + nH) ** 2
    return gain * (1.0 + 2.0 * gamma(n + p + 12))


def _w_factor(n: int, p: int) -> float:
    """``w``'s factor: ``y + |K| (|H| y)`` rounded up, sums of at most ``n + p + 4`` nonnegative terms (step 3)."""
    return 1.0 + 2.0 * gamma(n + p + 4)


def frobenius_bound(F: float, fK: float, fH: float, p: int, n: int) -> float:
    """``>= ||I - K H||_2`` (balanced) from ``F = fro_upper(fl(I - K H))`` there, ``fK = ||D^-1 K||_F``,
    ``fH = ||H D||_F`` (upper bounds) and ``H``'s shape ``(p, n)``. ``F`` misses what rounding takes
    from it, ``err``: the product's (``gamma_{p+2} fK fH`` and its underflow ``n (p + 2) eta``, ``D``
    being powers of two) and, with the norm's own rounding, the difference's (``u`` relative to each entry
    of ``fl(I - K H)``): both within ``gamma_{n^2+2} F``. ``I - K H`` is the identity on ``H``'s
    null space, of dimension ``>= n - p``: ``n - p`` singular values are ``>= 1``, so
    ``||.||_F^2 >= ||.||_2^2 + n - p - 1`` and ``||.||_F - ||.||_2 >= (n - p - 1) / (2 ||.||_F)``. Where
    that slack (with ``F + err`` for ``||.||_F``) covers ``err``, ``F`` itself bounds ``||.||_2``;
    else ``F + err``, rounded up."""
    err = (gamma(p + 2) * fK * fH + gamma(n * n + 2) * F + n * (p + 2) * UNDERFLOW) * (1.0 + 8.0 * UNIT_ROUNDOFF)
    if n - p >= 2 and err * (2.0 * (F + err)) * (1.0 + 8.0 * UNIT_ROUNDOFF) <= n - p - 1:
        return F
    return (F + err) * (1.0 + 2.0 * UNIT_ROUNDOFF)


def _columns(H: np.ndarray) -> tuple[tuple, int]:
    """``((c, H[:, c]), h)`` with ``c`` the columns of ``H`` that hold a nonzero (a channel sees a few
    states; ``()`` instead when they are more than a quarter of the columns) and ``h`` the most
    nonzeros in a row of ``H``; kept per ``H`` array."""
    hit = _COLUMNS.get(id(H))
    if hit is not None and hit[0] is H:
        return hit[1]
    nz = H != 0.0
    c = np.flatnonzero(np.any(nz, axis=0))
    out = ((c, H[:, c]) if 4 * c.size <= H.shape[1] else (), int(nz.sum(axis=1).max()) if H.size else 0)
    if len(_COLUMNS) > 256:
        _COLUMNS.clear()
    _COLUMNS[id(H)] = (H, out)
    return out


class KalmanMap:
    """The error map ``M = (I - K H) Phi~`` of one Kalman sample (module docstring).

    ``KalmanMap(entry, K, H)`` with ``entry`` the ZOH cache entry of the step (``Phi~``, its
    norms, its sparse form, its balancing ``scale``). ``M @ X`` multiplies by ``M`` (a held map of
    the observer's ``Phi``); :meth:`sandwich` is the bound's ``M S M'`` with its rounding's
    ``(w, c)``; :attr:`kappa` bounds ``||I - K H||_2`` in balanced coordinates.
    """

    __slots__ = ("Phi", "K", "H", "e", "_fK", "_fH", "_kappa", "_I", "_IKH", "_E", "_nIKH", "_sp", "_cols",
                 "_emap", "_Ks", "_Hs", "_aE", "_aKH", "_aEd", "_dense", "rho_form", "_kern")

    def __init__(self, entry: Any, K: np.ndarray, H: np.ndarray, identity: np.ndarray) -> None:
        self.Phi, self.K, self.H, self.e, self._I = entry.Phi, K, H, entry, identity
        self._fK: float | None = None
        self._fH: float | None = None
        self._kappa: float | None = None
        self._IKH: np.ndarray | None = None
        self._E: np.ndarray | None = None
        self._nIKH: float | None = None
        self._emap: float | None = None
        self._Ks: np.ndarray | None = None
        self._Hs: np.ndarray | None = None
        self._aE: tuple | None = None
        self._aEd: tuple | None = None      # (d, D |E~|) of dense_abs
        self._aKH: tuple | None = None      # (|K|, |H|, factored_underflow) of the factored step
        self._sp = sparse_transition(entry)
        self._cols: tuple | None = None
        self._dense: tuple | None = None    # (Phi~, H, K) C-ordered for the kernel's correct()
        self._kern: tuple | None = None     # (K C-ordered, H's rows, w's factor, c) for the kernel's factored step
        #: ``(bound, dt, coefficients, dense_abs(bound.d))`` of the bound's residual through this map
        #: (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.fused_sample`), kept with the map.
        self.rho_form: tuple | None = None

    def _scaled(self) -> tuple[np.ndarray, np.ndarray]:
        """``(D^-1 K, H D)`` in the entry's balancing."""
        if self._Ks is None:
            d = getattr(self.e, "scale", None)
            d = np.ones(self.K.shape[0]) if d is None else d
            self._Ks, self._Hs = self.K / d[:, None], self.H * d[None, :]
        return self._Ks, self._Hs

    @property
    def fK(self) -> float:
        """``||D^-1 K||_F`` (for the bound only: computed at its first read)."""
        if self._fK is None:
            self._fK = fro_upper(self._scaled()[0])
        return self._fK

    @property
    def fH(self) -> float:
        """``||H D||_F`` (computed at its first read)."""
        if self._fH is None:
            self._fH = fro_upper(self._scaled()[1])
        return self._fH

    @property
    def kappa(self) -> float:
        """``>= || I + |D^-1 K| |H D| ||_2 >= ||I - K H||_2`` (balanced): ``1 + sqrt(||.||_1 ||.||_inf)``
        of ``|K| |H|`` there, in O(n p) (module docstring); its sums rounded up by ``1 + 2 gamma_{n+2p+2}`` (in any
        order: on the factored path by the compiled kernel, :func:`~switchobs_core.numerics.dense_kernel.kappa`)."""
        if self._kappa is None:
            K, H = self.K, self.H
            hit = None      # the compiled kernel's sums on the factored path (in index order), where it runs
            if self._sp is not None and K.size and H.size:
                d = getattr(self.e, "scale", None)
                hit = dense_kernel.kappa(K, H, np.ones(K.shape[0]) if d is None else d)
            if hit is None:
                K, H = self._scaled()
                aK, aH = np.abs(K), np.abs(H)
                hit = (float((aK.sum(axis=0) @ aH).max()) if aH.size else 0.0,
                       float((aK @ aH.sum(axis=1)).max()) if aK.size else 0.0)
            one, inf = hit
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

    def dense(self) -> np.ndarray:
        """``M`` as a dense matrix ``fl(fl(I - K H) Phi~)``: :attr:`E` if it is kept, else formed and not
        kept (the factored path stays factored, and no n x n matrix stays with the map)."""
        if self._E is not None:
            return self._E
        return (self._I - self.K @ self.H) @ self.Phi

    @property
    def nIKH(self) -> float:
        """An upper bound of ``||I - K H||_2`` (balanced): ``||I - K H||_F`` there on the dense path
        (:func:`frobenius_bound`), :attr:`kappa` on the factored one (no n x n matrix formed)."""
        if self._nIKH is None:
            if self._sp is not None:
                self._nIKH = self.kappa
            else:
                d = self.e.scale
                F = fro_upper((self._ikh() / d[:, None]) * d[None, :])
                self._nIKH = min(frobenius_bound(F, self.fK, self.fH, *self.H.shape), self.kappa)
        return self._nIKH

    @property
    def emap(self) -> float:
        """``>= ||E~ - (I - K H) Phi~||_2`` (balanced) of the dense ``E~ = fl(fl(I - K H) Phi~)``:
        ``gamma_{p+1} kappa nu(Phi~) + gamma_n nu(I - K H) nu(Phi~)``; 0 on the factored path."""
        if self._emap is None:
            if self._sp is not None:
                self._emap = 0.0
            else:
                d = self.e.scale
                nP = self.e.nPhi
                nI = nu((self._ikh() / d[:, None]) * d[None, :])
                self._emap = (gamma(self.H.shape[0] + 1) * self.kappa * nP
                              + gamma(self.Phi.shape[0]) * nI * nP) * (1.0 + 8.0 * gamma(1))
        return self._emap

    def predict(self, x: np.ndarray) -> np.ndarray:
        """``x^- = Phi~ x`` (a new array; sparse when ``Phi~`` is)."""
        sp = self._sp
        return self.Phi @ x if sp is None else sp.matvec(x)

    def correct(self, x0: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x^-, nu, x^+)`` of a sample ``y``: ``x^- = Phi~ x0``, ``nu = y - H x^-`` (innovation first:
        rounding at the level of the error, not of ``||x||``), ``x^+ = x^- + K nu``; new arrays, by the compiled
        kernel where it takes the dense arrays (:func:`~switchobs_core.numerics.dense_kernel.correct`: its
        sums in another order, within the same ``gamma`` allowances), else numpy."""
        if self._sp is None and dense_kernel.CORRECT is not None:
            dn = self._dense
            if dn is None:
                dn = self._dense = tuple(np.ascontiguousarray(a, dtype=float) for a in (self.Phi, self.H, self.K))
            got = dense_kernel.correct(*dn, x0, y)
            if got is not None:
                return got
        x = self.predict(x0)
        nu = y - self.H @ x
        return x, nu, x + self.K @ nu

    @property
    def nbytes(self) -> int:
        return self.Phi.nbytes

    def __matmul__(self, other: np.ndarray) -> np.ndarray:
        if self._sp is not None and self._E is None:     # M X = Phi~ X - K (H (Phi~ X))
            PX = self._sp.matmat(other)
            return PX - self.K @ (self.H @ PX)
        return self.E @ other

    def dense_abs(self, d: np.ndarray | None = None) -> tuple | None:
        """``(|E~|, ||E~||_inf)`` of the dense map, with ``D |E~|`` third for a balancing ``d`` (kept for the
        last ``d``, compared by identity), or None on the factored path."""
        if self._sp is not None:
            return None
        aE, mn = self._abs()
        if d is None:
            return aE, mn
        if self._aEd is None or self._aEd[0] is not d:
            self._aEd = (d, aE * d[:, None])
        return aE, mn, self._aEd[1]

    def _abs(self) -> tuple[np.ndarray, float]:
        if self._aE is None:
            aE = np.abs(self.E)
            self._aE = (aE, float(aE.sum(axis=1).max()))
        return self._aE

    def sandwich(self, ell: Any) -> tuple[np.ndarray, np.ndarray, float, float]:
        """``(Z, w, c, mn)``: ``|Z - M S M'| <= c w w'`` entrywise for the ellipsoid's ``S`` (up to
        underflow), ``mn >= ||M||_inf`` for its underflow allowance.

        Dense: ``Z = E~ S E~'`` with :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.image_bound`
        (:mod:`switchobs_core.numerics.rounding`, step 6); factored: the module docstring's three
        products, ``w`` and ``c``."""
        S = ell.S
        sp = self._sp
        if sp is None:
            E = self.E
            aE, mn = self._abs()
            return E @ S @ E.T, ell.image_bound(aE), ell.c_dense, mn
        K, H = self.K, self.H
        Y = ell.take_product(sp)        # the prior's Phi~ S Phi~' at this sample, if it was kept
        if Y is None:
            Y = sp.sandwich_either(S, ell.scratch())   # C-ordered
        cols = self._cols
        if cols is None:
            cols = self._cols = _columns(H)
        cols, h = cols
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
        s = np.sqrt(np.maximum(np.diagonal(S), 0.0))
        y = sp.abs_matvec(s)
        if self._aKH is None:
            self._aKH = (np.abs(K), np.abs(H), factored_underflow(sp, K, H, h))
        aK, aH, mn = self._aKH
        w = (y + aK @ (aH @ y)) * _w_factor(n, p)
        return Z, w, _allowance(sp, h, p), mn

    def step(self, ell: Any, rho: float) -> bool:
        """The ellipsoid ``ell`` through this map with a residual ``rho`` (balanced), kept: :meth:`sandwich` and
        :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.propagate_product` in one call of the compiled
        kernel (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.step_factored`: the same products,
        allowances ``c`` and ``w``, every sum in index order). False (nothing changed; a product taken from the
        prior is kept again for :meth:`sandwich`) on the dense path or where the kernel is not built or refuses."""
        sp = self._sp
        if sp is None or dense_kernel.FACTORED is None:
            return False
        kh = self._kern
        if kh is None:
            p, n = self.H.shape
            rows, h = _rows(self.H)
            kh = self._kern = (factored_underflow(sp, self.K, self.H, h), np.ascontiguousarray(self.K, dtype=float),
                               rows, _w_factor(n, p), _allowance(sp, h, p))
        Y = ell.take_product(sp)
        if Y is None:
            Y = sp.sandwich_either(ell.S, ell.scratch())
        if ell.step_factored(Y, sp.abs_rows, *kh, rho):
            return True
        ell.keep_product(sp, Y)
        return False
