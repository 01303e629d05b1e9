"""Reading an error ellipsoid's bound ``sqrt(lambda_max(S))`` amortised: one eigenvalue problem
per anchor, an O(n^2) rigorous upper bound in between.

The published bound of an ellipsoid ``{e : e' S^-1 e <= 1}`` (:mod:`.rounding`, step 5) is
``||e|| <= sqrt(lambda_max(sym S))`` with ``sym S = (S + S') / 2``; solving the eigenvalue
problem is O(n^3) and was 41 % of a node's per-sample cost at n = 132 (bench/RESULTS.md, online
cost per sample). Here it is solved only at an *anchor* ``S_a`` (:meth:`~.rounding.ErrorEllipsoid.lam_upper`, its model
of the solver's error ``2 n u ||S_a||_F``, plus ``16 u ||S_a||_F`` for the rounding of ``sym S_a``
itself and a margin on that model, :data:`_SOLVER_MARGIN`: ``lam_a >= lambda_max(sym S_a)``; the
solver's error is a model, as the matrix exponential's is, checked against extended precision
in test_bound_read.py), and for a later ``S``:

1. Weyl's inequality: ``lambda_max(sym S) <= lambda_max(sym S_a) + lambda_max(sym D)`` with
   ``D = S - S_a``.
2. Gershgorin for the symmetric ``sym D``: ``lambda_max(sym D) <= ||sym D||_inf
   <= max(||D||_inf, ||D||_1) =: g`` (largest absolute row or column sum).
3. Floating point: ``D~ = fl(S - S_a)`` has ``|D| <= |D~| / (1 - u)`` entrywise; a row or
   column sum of ``n`` nonnegative terms is computed within ``gamma_n`` relative; so
   ``g <= g~ (1 + 2 gamma_{n+4})`` and ``lambda_max(sym S) <= (lam_a + g~ (1 + 2 gamma_{n+4}))
   (1 + 4u)`` (the last factor covers the two roundings of the sum and the product).
4. ``trace S`` (:attr:`~.rounding.ErrorEllipsoid.tr`, kept as an upper bound of the trace)
   bounds ``lambda_max`` too: the smaller of the two is published.

Re-anchoring: when ``g~ > tol lam_a`` (or after ``max_age`` reads) the eigenvalue problem is
solved for the current ``S``, which becomes the anchor. Looseness: between anchors
``lambda_max(sym S) >= lam_a' - g`` (Weyl the other way, ``lam_a'`` the anchor's exact value),
so the published value is at most ``(1 + tol) / (1 - tol)`` times the current one in
``lambda`` (plus the solver's allowance of the anchor), ``sqrt`` of that in the bound:
``1.051`` for the default ``tol = 0.05``.
"""

from __future__ import annotations

import math

import numpy as np

from .rounding import UNIT_ROUNDOFF, ErrorEllipsoid, _fro, gamma

__all__ = ["AnchoredBound"]

#: Extra allowance on the anchor's eigenvalue problem, in units of ``u ||S||_F``: ``lam_upper``'s
#: model (``2 n u ||S||_F``) was measured short for n = 3 (LAPACK's error 10.4 u ||S||_F against
#: an extended-precision power iteration; test_bound_read.py), and it omits the symmetrisation.
_SOLVER_MARGIN = 16.0


def _gershgorin(D: np.ndarray) -> float:
    """``max(||D||_inf, ||D||_1)`` as computed (step 3 inflates it)."""
    A = np.abs(D)
    return float(max(A.sum(axis=1).max(), A.sum(axis=0).max()))


class AnchoredBound:
    """``sqrt(lambda_max(sym S))`` upper bounds of an :class:`~.rounding.ErrorEllipsoid`'s
    current ``S``, amortised (module docstring). ``AnchoredBound(tol=0.05, max_age=256)``;
    ``read(ell)`` per read."""

    def __init__(self, tol: float = 0.05, max_age: int = 256) -> None:
        self.tol = float(tol)
        self.max_age = int(max_age)
        self.anchors = 0        # eigenvalue problems solved (for the measurements)
        self.reads = 0
        self._Sa: np.ndarray | None = None
        self._lam_a = math.inf
        self._tr_a = 0.0
        self._g_a = 0.0
        self._age = 0

    def read(self, ell: ErrorEllipsoid) -> float:
        """An upper bound of ``||e||`` for the ellipsoid's current ``S`` (module docstring)."""
        S = ell.S
        n = ell.n
        self.reads += 1
        if not n:
            return 0.0
        if self._Sa is not None and self._Sa.shape == S.shape and self._age < self.max_age \
                and np.isfinite(self._lam_a) and self._tr_a > 0.0:
            infl = 1.0 + 2.0 * gamma(n + 4)
            c = max(ell.tr, 0.0) / self._tr_a      # any c >= 0 is valid; this one follows a uniform shrink
            g = (_gershgorin(S - c * self._Sa) + UNIT_ROUNDOFF * c * self._g_a) * infl
            if math.isfinite(g) and g <= self.tol * c * self._lam_a:
                self._age += 1
                lam = (c * self._lam_a + g) * (1.0 + 4.0 * UNIT_ROUNDOFF)
                lam = min(lam, max(ell.tr, 0.0))
                return math.sqrt(lam) * (1.0 + 2.0 * UNIT_ROUNDOFF)
        # the eigenvalue problem, plus the rounding of the symmetrisation (S + S') / 2 when S is
        # not exactly symmetric (entrywise relative u: ||.||_2 <= u ||S||_F) and a margin on the
        # solver's model (module docstring): 16 u ||S||_F more in all
        lam = (ell.lam_upper(S) + _SOLVER_MARGIN * UNIT_ROUNDOFF * _fro(S)) * (1.0 + 2.0 * UNIT_ROUNDOFF)
        self.anchors += 1
        self._Sa = S.copy()
        self._lam_a = lam
        self._tr_a = max(ell.tr, 0.0)
        self._g_a = _gershgorin(S)
        self._age = 0
        return math.sqrt(lam)
