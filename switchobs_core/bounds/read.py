"""Reading an error ellipsoid's bound ``sqrt(lambda_max(S))`` amortised: an O(n^3) upper bound
per anchor, an O(n^2) rigorous upper bound in between.

The published bound of an ellipsoid ``{e : e' S^-1 e <= 1}`` (:mod:`switchobs_core.numerics.rounding`, step 5) is
``||e|| <= sqrt(lambda_max(sym S))`` with ``sym S = (S + S') / 2``; solving the eigenvalue
problem is O(n^3) and was 41 % of a node's per-sample cost at n = 132 (bench/RESULTS.md, online
cost per sample). Here an upper bound ``lam_a >= lambda_max(sym S_a)`` is computed only at an
*anchor* ``S_a``, and for a later ``S``:

1. Weyl's inequality, for any scalar ``c >= 0``: ``lambda_max(sym S) <= c lambda_max(sym S_a) +
   lambda_max(sym D)`` with ``D = S - c S_a``. ``c`` follows the anchor's leading direction
   ``v_a`` (a unit vector): ``c = v_a' S v_a / v_a' S_a v_a`` (one matrix-vector product; a
   ratio of traces let ``D`` grow when the ellipsoid narrows, and forced an anchor every few
   samples).
2. ``lambda_max(sym D) <= ||sym D||_2 <= ||D||_F`` (one pass over ``D``; as tight as the
   2-norm when ``D`` has low rank, as the change of a narrowing ellipsoid has), and when that
   is not enough Gershgorin's ``lambda_max(sym D) <= max(||D||_inf, ||D||_1)`` (largest absolute
   row or column sum: the tighter one when ``D`` is spread over many directions; the rows alone when
   ``S`` and ``S_a`` are exactly symmetric, :attr:`~switchobs_core.numerics.rounding.ErrorEllipsoid.symmetric`:
   then so is ``D``, whose row and column sums agree): ``g`` is the smaller.
3. Floating point: ``D~ = fl(S - fl(c S_a))`` has ``|D| <= (|D~| + u c |S_a|) / (1 - u)``
   entrywise, so ``||D||_F <= (||D~||_F + u c ||S_a||_F) / (1 - u)`` and likewise for the row
   and column sums; a computed sum of ``m`` nonnegative terms (in any order) is within
   ``gamma_m`` of the exact one and a square root within ``u``: ``g <= (g~ + u c g_a)(1 + 2
   gamma_{m+4})`` with ``m = n^2`` (Frobenius) or ``n`` (Gershgorin) and ``g_a`` the anchor's
   norm of the same kind, rounded up alike; then ``lambda_max(sym S) <= (c lam_a + g) (1 + 4u)``
   (the last factor covers the two roundings of the sum and the product).
4. ``trace S`` (:attr:`~switchobs_core.numerics.rounding.ErrorEllipsoid.tr`, kept as an upper bound of the trace)
   bounds ``lambda_max`` too: the smaller of the two is published.

The anchor's ``lam_a``:

* below :data:`CHOLESKY_MIN_N` states, the eigenvalue problem
  (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.lam_upper`, its model of the solver's error
  ``2 n u ||S_a||_F``, plus ``16 u ||S_a||_F`` for the rounding of ``sym S_a`` itself and a
  margin on that model, :data:`_SOLVER_MARGIN`; the solver's error is a model, checked against
  extended precision in test_read.py);
* from :data:`CHOLESKY_MIN_N` states on, a *verified* candidate (ten times cheaper than the
  eigenvalue problem at n = 132, and no model of a solver): ``T = fl(sym S_a)`` is exactly
  symmetric with ``||T - sym S_a||_2 <= u ||S_a||_F``; power iterations from the last leading
  direction give the Rayleigh quotient ``theta <= lambda_max(T)``; the candidate
  ``l = theta (1 + delta)`` is proved an upper bound when the Cholesky factorisation of
  ``fl(A~ - c_R I)``, ``A~ = fl(l I - T)``, runs to completion with Rump's shift
  ``c_R >= gamma_{n+1} / (1 - 2 gamma_{n+1}) trace(A~) + 4 n (2 (n + 2) + max a~_ii) eta_min``
  (S. M. Rump, *Verification of positive definiteness*, BIT 46 (2006), Theorem 2.3; doubled here
  as a margin): then ``A~`` is positive definite, and since ``A~`` differs from ``l I - T`` by
  the rounding of its diagonal (``|.| <= u (l + max |t_ii|)``),
  ``lambda_max(sym S_a) < l + u (l + max |t_ii|) + u ||S_a||_F``. If the factorisation fails the
  candidate was too low: ``delta`` grows (:data:`_DELTAS`), and after the last one the eigenvalue
  problem decides. The candidates stop at ``delta = 0.05`` (a candidate 50 % above the Rayleigh
  quotient was accepted once, and an anchor came out 34 % above ``lambda_max``): before the
  eigenvalue problem, :data:`_MORE_POWER_STEPS` further power iterations move the quotient closer
  and the candidates are tried again.

Re-anchoring: when ``g > tol c lam_a`` (or after ``max_age`` reads) a new anchor is taken.

Looseness, proven. Let ``lam*`` be ``lambda_max(sym S)`` and ``lam_a*`` the anchor's. The anchor
is within ``lam_a <= (1 + delta_max) lam_a* (1 + 8 n u)`` of it (a verified candidate is ``(1 +
delta) theta`` with ``theta <= lam_a*`` a Rayleigh quotient, plus its ``u`` terms; the eigenvalue
problem's is ``lam_a*`` plus ``(2n + 16) u ||S_a||_F``). Between anchors, Weyl the other way:
``lam* >= c lam_a* - ||sym D||_2 >= c lam_a / (1 + delta_max) - g``, and the published value is at
most ``(c lam_a + g)(1 + 4u)`` with ``g <= tol c lam_a``. So published / ``lam*`` is at most
``(1 + tol)(1 + delta_max) / (1 - tol (1 + delta_max))`` up to the ``u`` terms: 1.1636 for the
defaults ``tol = 0.05`` and ``delta_max = 0.05``, and :data:`LOOSENESS` = ``sqrt`` of that, 1.079,
for the bound (an anchor alone: at most 1.025). The published value is also capped by
``sqrt(trace S)``, which only lowers it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.blas import daxpy as _daxpy
from scipy.linalg.lapack import dpotrf, dsyevr

from ..numerics import dense_kernel
from ..numerics.frobenius import SQRT_ETA as _SQRT_ETA
from ..numerics.frobenius import fro_upper
from ..numerics.rounding import UNDERFLOW, UNIT_ROUNDOFF, ErrorEllipsoid, fro_norm, gamma

__all__ = ["AnchoredBound", "AMORTISED_MIN_N", "CHOLESKY_MIN_N", "LOOSENESS", "positive_definite",
           "verified_lambda_max"]

#: Fewest states from which :meth:`~switchobs_core.runtime.observer.SwitchedObserver.envelope` reads the
#: bound amortised by default (below, the eigenvalue problem costs no more than this module's
#: bookkeeping, and its bound is the tighter one). Measured on ``camera_agents`` with a Kalman
#: table, update + envelope() per sample (bench/RESULTS.md): equal at n = 28 (71 us), amortised
#: 17 % cheaper at n = 36 (86 against 103 us), its bound at most 2.5 % above the eigenvalue
#: problem's.
AMORTISED_MIN_N = 32

#: Extra allowance on the anchor's eigenvalue problem, in units of ``u ||S||_F``: ``lam_upper``'s
#: model (``2 n u ||S||_F``) was measured short for n = 3 (LAPACK's error 10.4 u ||S||_F against
#: an extended-precision power iteration; test_read.py), and it omits the symmetrisation.
_SOLVER_MARGIN = 16.0
#: Fewest states for which the anchor is a Cholesky-verified candidate (module docstring).
CHOLESKY_MIN_N = 40
#: The candidate's margins over the Rayleigh quotient, tried in turn (``delta_max`` the last).
_DELTAS = (0.02, 0.05)
#: Power iterations per anchor (from the last leading direction).
_POWER_STEPS = 8
#: Further power iterations before the candidates are tried a second time.
_MORE_POWER_STEPS = 24
#: The largest ratio of a published bound to ``sqrt(lambda_max(sym S))`` (module docstring), for the
#: default ``tol = 0.05``, apart from relative terms of order ``n u``.
LOOSENESS = math.sqrt(1.05 * (1.0 + _DELTAS[-1]) / (1.0 - 0.05 * (1.0 + _DELTAS[-1])))
#: The eigenvalue problem's absolute tolerance (LAPACK ``dsyevr``'s ``ABSTOL``): the smallest normal double,
#: LAPACK's setting for the most accurate eigenvalues (bisection to full accuracy, not ``ulp ||T||_1``).
_ABSTOL = float(np.finfo(float).tiny)
#: The smallest positive double (Rump's underflow term).
_ETA_MIN = 5e-324


def _minus_scaled(S: np.ndarray, c: float, Sa: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``fl(S - c S_a)`` in two passes (a copy and one BLAS ``axpy``, fused multiply-add or not:
    either is within step 3's allowance); ``out``: a C-ordered array of ``S``'s shape to hold it (the
    same doubles as a new one)."""
    if S.flags.c_contiguous and Sa.flags.c_contiguous:
        if out is None or out.shape != S.shape or not out.flags.c_contiguous:
            D = S.copy()
        else:
            D = out
            np.copyto(D, S)
        _daxpy(Sa.ravel(), D.ravel(), a=-c)
        return D
    return S - c * Sa


def _between(S: np.ndarray, Sa: np.ndarray, va: np.ndarray, theta_a: float,
             D: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """:func:`~switchobs_core.numerics.dense_kernel.between` in numpy: ``(w, c, ||w||, ||D||_F)`` with
    ``w = S v_a``, ``c = v_a' w / theta_a`` and ``D = fl(S - fl(c S_a))`` in ``D`` (:func:`_minus_scaled`;
    its norm nan where ``c`` is not finite and ``>= 0``)."""
    w = S.dot(va)
    c = float(va.dot(w)) / theta_a
    if not (math.isfinite(c) and c >= 0.0):
        return w, c, math.sqrt(float(w.dot(w))), math.nan
    Dm = _minus_scaled(S, c, Sa, D)
    if Dm is not D:         # S or S_a not C-ordered: a new array, copied into the caller's
        np.copyto(D, Dm)
    return w, c, math.sqrt(float(w.dot(w))), fro_norm(D)


def _abs_rows(D: np.ndarray, n: int, ones: np.ndarray) -> float:
    """``max_i sum_j |D_ij|`` of the n x n ``D`` (a computed sum, any order: step 3), by the compiled kernel
    where it takes ``D``, else numpy (``D`` then overwritten by ``|D|``; no overflow warns); NaN where a row's
    sum is."""
    if dense_kernel.ABSROWS is not None:
        try:
            return dense_kernel.ABSROWS(D, n)
        except (BufferError, ValueError, TypeError):
            pass
    with np.errstate(over="ignore", invalid="ignore"):
        r = np.abs(D, out=D).dot(ones)
        return math.nan if np.isnan(r).any() else float(r.max())


def _leading(T: np.ndarray, v: np.ndarray | None, steps: int) -> tuple[float, np.ndarray]:
    """``(theta, v)``: a lower bound of ``lambda_max(T)`` (up to rounding): the larger of the
    Rayleigh quotient ``v' T v`` after ``steps`` power iterations and the largest diagonal entry
    (``e_i' T e_i``). The start is the last leading direction ``v`` plus the axis of the largest
    diagonal entry plus a little of every axis: a warm ``v`` alone can lie in a block of ``T``
    uncoupled from the one that now leads (bodies that do not interact), where power iterations
    never leave it."""
    n = T.shape[0]
    d = np.diagonal(T)
    i = int(np.argmax(d))
    start = np.full(n, 1.0 / n)
    start[i] += 1.0
    if v is not None and v.shape == (n,) and np.all(np.isfinite(v)) and float(v @ v) > 0.0:
        start += v / math.sqrt(float(v @ v))
    v = start / math.sqrt(float(start @ start))
    theta = 0.0
    for _ in range(steps):
        w = T @ v
        theta = float(v @ w)
        nw = math.sqrt(float(w @ w))
        if not nw > 0.0 or not math.isfinite(nw):
            break
        v = w / nw
    return max(theta, float(d[i])), v


def verified_lambda_max(S: np.ndarray, v: np.ndarray | None = None,
                        nS: float | None = None) -> tuple[float, np.ndarray] | None:
    """``(lam, v)`` with ``lam >= lambda_max((S + S') / 2)`` proved by a Cholesky factorisation
    (module docstring), ``v`` the leading direction found on the way; None if no candidate of
    :data:`_DELTAS` could be verified (the caller solves the eigenvalue problem). ``nS``: ``fro_upper(S)``
    when the caller has it."""
    n = S.shape[0]
    u = UNIT_ROUNDOFF
    T = S + S.T
    T *= 0.5                                    # exactly symmetric (the sum commutes)
    theta, v = _leading(T, v, _POWER_STEPS)
    d = np.diagonal(T)
    dmax = float(np.abs(d).max())
    if nS is None:
        nS = fro_upper(S)
    if not (theta > 0.0 and math.isfinite(theta) and math.isfinite(nS)):
        return None
    gn = gamma(n + 1)
    for attempt in range(2):
        if attempt:             # the quotient was too far below lambda_max: iterate on
            theta, v = _leading(T, v, _MORE_POWER_STEPS)
        for delta in _DELTAS:
            lc = theta * (1.0 + delta)
            A = -T
            A.flat[:: n + 1] += lc                  # A~ = fl(lc I - T): only the diagonal rounds
            if positive_definite(A, gn):
                lam = (lc + u * (lc + dmax) + 2.0 * u * nS) * (1.0 + 4.0 * u) + 8 * n * UNDERFLOW
                return lam, v
    return None


def positive_definite(A: np.ndarray, gn: float | None = None) -> bool:
    """Whether the exactly symmetric float matrix ``A`` is proved positive definite by Rump's test
    (module docstring: the Cholesky factorisation of ``fl(A - c_R I)`` runs to completion; ``gn``
    is ``gamma_{n+1}``). ``A`` is overwritten."""
    n = A.shape[0]
    gn = gamma(n + 1) if gn is None else gn
    ad = np.diagonal(A)
    if not n or not float(ad.min()) > 0.0:
        return False
    tr = float(ad.sum()) * (1.0 + 2.0 * n * UNIT_ROUNDOFF)
    cr = 2.0 * (gn / (1.0 - 2.0 * gn) * tr + 4.0 * n * (2.0 * (n + 2) + float(ad.max())) * _ETA_MIN)
    if not math.isfinite(cr):
        return False
    A.flat[:: n + 1] -= cr                  # fl(A~ - c_R I), as the theorem has it
    _, info = dpotrf(A, lower=1, clean=0, overwrite_a=1)
    return info == 0


def _eigen_anchor(S: np.ndarray) -> tuple[float, np.ndarray]:
    """``(lam, v)`` below :data:`CHOLESKY_MIN_N` states: one symmetric eigenvalue problem for the largest
    eigenpair alone (LAPACK ``dsyevr``, bisection and inverse iteration after the tridiagonal reduction:
    a third of the cost of all pairs at n = 36; all pairs where it reports none) gives both the anchor's
    ``lam`` (the largest eigenvalue of ``T = fl(sym S)`` plus the model of the solver's error,
    ``2 n u ||T||_F + 4 n eta`` as :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.lam_upper` has it, plus
    :data:`_SOLVER_MARGIN` ``u ||S||_F``, rounded up) and its leading direction ``v``; ``inf`` and the
    uniform direction where ``S`` is not finite or the solver does not converge."""
    n = S.shape[0]
    u = UNIT_ROUNDOFF
    T = S + S.T
    T *= 0.5
    nT, nS = fro_upper(T), fro_upper(S)
    flat = np.full(n, 1.0 / math.sqrt(n))
    if not (math.isfinite(nT) and math.isfinite(nS)):
        return math.inf, flat
    # the largest pair alone; all pairs where LAPACK reports none found (a cluster of equal eigenvalues)
    w, V, m, _, info = dsyevr(T.T, compute_v=1, range="I", il=n, iu=n, abstol=_ABSTOL)
    if info == 0 and m == 1:
        top, v = float(w[0]), V[:, 0]
    else:
        try:
            w, V = np.linalg.eigh(T)
        except np.linalg.LinAlgError:
            return math.inf, flat
        top, v = float(w[-1]), V[:, -1]
    if not math.isfinite(top):
        return math.inf, flat
    return (max(top, 0.0) + 2 * n * u * nT + 4 * n * UNDERFLOW + _SOLVER_MARGIN * u * nS) * (1.0 + 2.0 * u), v


class AnchoredBound:
    """``sqrt(lambda_max(sym S))`` upper bounds of an :class:`~switchobs_core.numerics.rounding.ErrorEllipsoid`'s
    current ``S``, amortised (module docstring). ``AnchoredBound(tol=0.05, max_age=256)``;
    ``read(ell)`` per read."""

    def __init__(self, tol: float = 0.05, max_age: int = 256) -> None:
        self.tol = float(tol)
        self.max_age = int(max_age)
        self.anchors = 0        # anchors taken (for the measurements)
        self.verified = 0       # of which by a verified candidate (no eigenvalue problem)
        self.reads = 0
        self._Sa: np.ndarray | None = None
        self._lam_a = math.inf
        self._va: np.ndarray | None = None      # the anchor's leading direction (unit)
        self._theta_a = 0.0                     # v_a' S_a v_a
        self._v: np.ndarray | None = None       # the latest leading direction (warm start)
        self._w: tuple | None = None            # (w, ||w||) of the latest read: v = w / ||w||, formed when anchoring
        self._f_a = self._g_a = 0.0   # ||S_a||_F and max(||S_a||_inf, ||S_a||_1), rounded up
        self._age = 0
        self._sym_a = False     # S_a exactly symmetric (step 2: Gershgorin from the rows alone)
        self._one: np.ndarray | None = None
        self._k: tuple | None = None

    def _ones(self, n: int) -> np.ndarray:
        """``n`` ones (kept)."""
        o = self._one
        if o is None or o.size != n:
            o = self._one = np.ones(n)
        return o

    def _constants(self, n: int) -> tuple[int, float, float, float, float]:
        """``(n, 1 + 2 gamma_{n^2+4}, 1 + 2 gamma_{n+4}, n sqrt(eta), 8 n eta)``: step 3's factors for ``n``
        states (kept: the same doubles as computed at each read)."""
        k = self._k
        if k is None or k[0] != n:
            k = self._k = (n, 1.0 + 2.0 * gamma(n * n + 4), 1.0 + 2.0 * gamma(n + 4), n * _SQRT_ETA,
                           8 * n * UNDERFLOW)
        return k

    def read(self, ell: ErrorEllipsoid) -> float:
        """An upper bound of ``||e||`` for the ellipsoid's current ``S`` (module docstring). Sets no
        floating-point error state of its own on the kernel's path between anchors (no numpy operation
        runs there); numpy's paths (the fallbacks, the anchor) run under one, so no overflow warns."""
        S = ell.S
        n = ell.n
        self.reads += 1
        if not n:
            return 0.0
        Sa = self._Sa
        if Sa is not None and Sa.shape == S.shape and self._age < self.max_age \
                and math.isfinite(self._lam_a) and self._theta_a > 0.0:
            D = ell.scratch()       # the step's scratch: in cache
            got = dense_kernel.between(S, Sa, self._va, self._theta_a, D)
            if got is None:
                with np.errstate(over="ignore", invalid="ignore"):
                    got = _between(S, Sa, self._va, self._theta_a, D)
            w, c, nw, fd = got      # any c >= 0 is valid (step 1)
            if math.isfinite(c) and c >= 0.0:
                if nw > 0.0 and math.isfinite(nw):
                    self._w = (w, nw)                   # one power iteration for the next anchor
                _, kf, kg, nsq, uf = self._constants(n)
                g = (fd + nsq + UNIT_ROUNDOFF * c * self._f_a) * kf
                if not g <= self.tol * c * self._lam_a:         # Gershgorin, before a new anchor
                    if self._sym_a and S is ell.symmetric:      # so is S - c S_a: its rows' sums are its columns'
                        gg = _abs_rows(D, n, self._ones(n))
                    else:
                        with np.errstate(over="ignore", invalid="ignore"):
                            A = np.abs(D, out=D)        # D is not read again
                            gg = float(max(A.sum(axis=1).max(), A.sum(axis=0).max()))
                    g = min(g, (gg + UNIT_ROUNDOFF * c * self._g_a) * kg)
                if math.isfinite(g) and g <= self.tol * c * self._lam_a:
                    self._age += 1
                    lam = (c * self._lam_a + g) * (1.0 + 4.0 * UNIT_ROUNDOFF) + uf
                    lam = min(lam, max(ell.tr, 0.0))
                    return math.sqrt(lam) * (1.0 + 2.0 * UNIT_ROUNDOFF)
        with np.errstate(over="ignore", invalid="ignore"):
            return self._anchor(ell)

    def _anchor(self, ell: ErrorEllipsoid) -> float:
        """A new anchor at the current ``S``: its ``lam_a`` (module docstring) is published."""
        S = ell.S
        if self._w is not None:     # the latest read's power iteration, normalised
            w, nw = self._w
            self._v, self._w = w / nw, None
        nS = fro_upper(S)           # the anchor's ||S_a||_F (below), the candidate's too
        got = verified_lambda_max(S, self._v, nS) if ell.n >= CHOLESKY_MIN_N else None
        if got is not None:
            lam, v = got
            self.verified += 1
        elif ell.n < CHOLESKY_MIN_N:
            lam, v = _eigen_anchor(S)
        else:
            # the eigenvalue problem, plus the rounding of the symmetrisation (S + S') / 2 when S is
            # not exactly symmetric (entrywise relative u: ||.||_2 <= u ||S||_F) and a margin on the
            # solver's model (module docstring): 16 u ||S||_F more in all
            lam = (ell.lam_upper(S) + _SOLVER_MARGIN * UNIT_ROUNDOFF * nS) * (1.0 + 2.0 * UNIT_ROUNDOFF)
            T = S + S.T
            T *= 0.5
            if np.all(np.isfinite(T)):      # the leading direction
                v = _leading(T, self._v, _POWER_STEPS)[1]
            else:
                v = np.full(ell.n, 1.0 / math.sqrt(ell.n))
        self.anchors += 1
        self._Sa = S.copy()
        self._sym_a = S is ell.symmetric
        self._lam_a = lam
        self._va = self._v = v = np.ascontiguousarray(v)      # the same doubles; what the kernel reads
        self._theta_a = float(v.dot(S.dot(v)))
        self._f_a = nS * (1.0 + 2.0 * gamma(S.size + 4))
        A = np.abs(S)
        self._g_a = float(max(A.sum(axis=1).max(), A.sum(axis=0).max())) * (1.0 + 2.0 * gamma(ell.n + 4))
        self._age = 0
        return math.sqrt(min(lam, max(ell.tr, 0.0)))
