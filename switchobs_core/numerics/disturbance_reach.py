"""A rigorous bound on what a bounded unknown input can add to the state over one step.

The plant with a bounded unknown input (beyond the paper's e:system, which has none) is

.. math::

    \\dot x = A x + B u + B_w w, \\qquad |w_j(t)| \\le m_j ,

so over a step of length ``h`` the state moves by the undisturbed step plus

.. math::

    d(h) = \\int_0^h e^{A (h - s)} B_w w(s) \\, ds = \\int_0^h e^{A r} B_w w(h - r) \\, dr ,

whatever the (measurable) ``w`` inside the box. The observer does not see ``w``, so ``d(h)`` joins
the error of every step (e:xtilde_dyn_piecewise gains the term ``-d``). :class:`DisturbanceReach`
gives ``R(h) >= ||D^-1 d(h)||`` for every such ``w``, in the balanced units ``D`` of
:mod:`switchobs_core.numerics.scaling` in which the rounding bound takes every residual
(:mod:`switchobs_core.numerics.rounding`, step 5: the ball the residual lies in). Write
``A_b = D^-1 A D`` and ``b_j = D^-1 B_w e_j`` (both exact: ``D`` holds powers of two), and
``a >= ||A_b||_2`` (:func:`~switchobs_core.numerics.expm_bound.nu`). Two bounds, the smaller is taken:

1. per column: ``||D^-1 d|| <= sum_j m_j int_0^h ||e^{A_b r} b_j|| dr``;
2. joint: ``||D^-1 d|| <= ||m|| int_0^h ||e^{A_b r} B_b||_2 dr`` (``B_b = D^-1 B_w``; Cauchy-Schwarz
   with ``||w|| <= ||m||``);
3. Gram: with ``e^{A_b r} B_b = B_b + r Y + R(r)`` (``Y = A_b B_b``, ``R`` below) and
   ``||X w||^2 = w' X'X w <= m' |X'X| m =: g(X)^2`` for ``|w| <= m``:
   ``||D^-1 d|| <= h g(B_b) + h^2 g(Y) / 2 + sum_j m_j ||A_b^2 b_j|| h^3 e^{a h} / 6`` (or
   ``g(B_b) (e^{a h} - 1) / a``). Exact up to ``O(h)`` relative when the columns act on orthogonal
   directions (a unit acceleration on each of ``q`` velocities of different scales), where 1 is
   ``sqrt(q)`` and 2 up to ``sqrt(q) max_j ||b_j|| / min_j ||b_j||`` times too large.

Each integral ``int_0^h ||e^{A_b r} X|| dr`` (``X`` a column or ``B_b``) is bounded by the smaller of

* Taylor: ``e^{A_b r} X = X + r A_b X + R(r)`` with ``||R(r)|| <= ||A_b^2 X|| (e^{a r} - 1 - a r) / a^2
  <= ||A_b^2 X|| r^2 e^{a r} / 2``; the norm of the affine part is convex in ``r``, so its integral
  is at most the trapezoid ``h (||X|| + ||X + h A_b X||) / 2``, and the remainder integrates to at
  most ``||A_b^2 X|| h^3 e^{a h} / 6``. For a double integrator (``A_b^2 B_b = 0``) this is the
  exact worst case up to the trapezoid's ``O(h^2)``;
* growth: ``||e^{A_b r}|| <= e^{a r}`` gives ``||X|| (e^{a h} - 1) / a`` (long steps).

The observer keeps its error in ellipsoids (:mod:`switchobs_core.numerics.rounding`, step 7), and a
ball in balanced units covers every direction, also those ``B_w`` cannot reach (positions, for
accelerations: ``h^2 / 2`` of the velocities' ``h``), and a map that expands some directions (a
Kalman correction's ``I - K H``, 200 in the balanced 2-norm for the paper's gains) expands the ball
in all of them. :meth:`DisturbanceReach.shaped` keeps the first two Taylor terms of ``d`` as a
degenerate ellipsoid ``E(G G')`` in the directions ``B_w`` and ``A B_w`` reach (a box of ``q``
inputs lies in the ellipsoid ``q diag(m^2)``) and only the third-order remainder,
``sum_j m_j ||A_b^2 b_j|| h^3 e^{a h} / 6``, as a ball.

Rounding. The products ``Y = fl(A_b X)`` and ``Z = fl(A_b Y)`` err by at most
``gamma_n |A_b| |X|`` entrywise (Higham, eq. 3.11), so ``||A_b X - Y|| <= gamma_n a ||X||``; the
axpy ``fl(X + h Y)`` by ``gamma_2 (|X| + h |Y|)``; a computed norm is a sum of nonnegative terms
rounded up by ``1 + gamma_{n+2}``, plus what underflow hides from it (``sqrt(m eta)`` for ``m``
squares, :mod:`switchobs_core.numerics.frobenius`; the Gram bound's form likewise); a matrix's
2-norm is bounded by ``min(nu, ||.||_F)``, both rounded up; ``h`` is taken as ``dt (1 + 2u)`` (the
true step is within ``u dt`` of the double ``dt``), and every line of the bookkeeping is inflated
by a relative ``8 u``. The result is an upper bound of the quantities above (``inf`` when a bound
is ``inf``: the disturbance then makes the bound infinite and the caller withdraws it).

Underflow. ``d`` is linear in ``B_w`` and in ``m``: both are scaled by powers of two to largest entries
in ``[1/2, 1)``, the bounds computed and multiplied back by ``2^k``, so a product falls under
``2^-1022`` only where it is that small against the problem's own scale; there it loses at most
``eta / 2``, allowed for by an absolute ``2 (q + 2) eta`` before the scaling back (:func:`_back`). An
entry more than ``2^1021`` below its largest scales under ``2^-1022`` and rounds: ``m_j`` is rounded
up (the reach grows with each ``m_j``), and ``B_b``'s rounding ``E`` (``||E|| <= sqrt(n q) eta / 2``)
reaches at most ``||E|| ||m|| (e^{a h} - 1) / a``, added to every bound. A step below ``2^-1022`` is
taken as ``2^-1022`` (the reach grows with the step), and the growth bound's ``(e^{a h} - 1) / a`` is
``h`` where ``a h`` is below ``2^-1022`` (:func:`_growth`). A bound that is ``nan`` (an ``inf`` times
0) bounds nothing and is dropped; without another the result is ``inf``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.linalg import expm

from .expm_bound import nu
from .frobenius import sum_slack, underflow_slack
from .rounding import NORMAL, UNDERFLOW, UNIT_ROUNDOFF, gamma

__all__ = ["DisturbanceReach", "brute_force_reach"]

_U = UNIT_ROUNDOFF
_UP = 1.0 + 8.0 * _U
#: Radii kept per step length (the observer's steps take a handful of lengths).
_CACHE = 256


def _norm_up(v: np.ndarray) -> float:
    """``>= ||v||_2`` (a sum of squares rounded up, plus what underflow hides from it:
    :func:`~switchobs_core.numerics.frobenius.sum_slack`)."""
    s = float(v @ v)
    return math.sqrt(s) * (1.0 + gamma(v.size + 2)) * _UP + sum_slack(s, v.size)


def _mat_norm_up(X: np.ndarray) -> float:
    """``>= ||X||_2``: the smaller of ``nu(X)`` and ``||X||_F`` (:func:`_mat_fro_up`), each rounded up."""
    if X.size == 0:
        return 0.0
    return min(nu(X), _mat_fro_up(X))


class DisturbanceReach:
    """``R(h) >= ||D^-1 d(h)||`` for every ``|w_j| <= m_j`` (module docstring).

    ``r = DisturbanceReach(A, B_w, w_max, scale=d)``; ``r.radius(dt)``. ``scale`` is the balancing
    of ``A`` (:func:`~switchobs_core.numerics.scaling.balance`; default none: ``D = I``).
    """

    def __init__(self, A: np.ndarray, B_w: np.ndarray, w_max: Sequence[float], scale: np.ndarray | None = None):
        A = np.asarray(A, dtype=float)
        n = A.shape[0]
        d = np.ones(n) if scale is None else np.asarray(scale, dtype=float)
        self.w_max = np.asarray(w_max, dtype=float).reshape(-1)
        Bw = np.asarray(B_w, dtype=float).reshape(n, -1)
        keep = self.w_max > 0.0
        self.w_max, Bw = self.w_max[keep], Bw[:, keep]
        Bb = Bw / d[:, None]        # exact: powers of two
        self._id = 1.0 / d
        self._e = np.frexp(d)[1] - 1            # d = 2^e
        # B_b and m scaled by powers of two to largest entries in [1/2, 1): R is linear in each, so
        # the reach of the scaled pair times 2^k is R's (Underflow, in the module docstring)
        kb, kw = _exponent(Bb), _exponent(self.w_max)
        Bs, self._m = np.ldexp(Bb, -kb), np.ldexp(self.w_max, -kw)
        # an entry scaled under 2^-1022 rounds: m_j up (R grows with each m_j), B_b's by <= eta / 2 each,
        # ||E||_2 <= sqrt(n q) eta / 2: its reach, ||E|| ||m|| (e^{a h} - 1) / a, joins every bound
        low = np.ldexp(self._m, kw) != self.w_max
        self._m[low] = np.nextafter(self._m[low], math.inf)
        self._eB = math.sqrt(Bs.size) * _UP if np.any(np.ldexp(Bs, kb) != Bb) else 0.0
        Bb, self._kb, self._k = Bs, kb, kb + kw
        self.q = Bb.shape[1]
        Ab = A * (1.0 / d)[:, None] * d[None, :]
        self.a = nu(Ab)
        gn = gamma(n)
        Y = Ab @ Bb
        Z = Ab @ Y
        self._B, self._Y = Bb, Y
        # columns: ||b_j||, the error of y_j, ||A_b^2 b_j||
        self._nb = np.array([_norm_up(Bb[:, j]) for j in range(self.q)])
        self._ny = ny = np.array([_norm_up(Y[:, j]) for j in range(self.q)])
        self._ey = gn * self.a * self._nb * _UP
        self._nz = np.array([_norm_up(Z[:, j]) + gn * self.a * ny[j] + self.a * self._ey[j]
                             for j in range(self.q)]) * _UP
        # the whole matrix: ||B_b||_2, the error of Y, ||A_b^2 B_b||_2 (upper bounds)
        self._mB = _mat_norm_up(Bb)
        mY = _mat_norm_up(Y)
        self._meY = gn * self.a * self._mB * _UP
        self._mZ = (_mat_norm_up(Z) + gn * self.a * mY + self.a * self._meY) * _UP
        self._mnorm = _norm_up(self._m)
        # Gram: g(B_b), g(Y) (its rounding and Y's error included), sum_j m_j ||A_b^2 b_j||
        self._gB = _gram(Bb, self._m, gn)
        self._gY = (_gram(Y, self._m, gn) + float(self._m @ self._ey)) * _UP
        self._gZ = float(self._m @ self._nz) * (1.0 + gamma(self.q + 2)) * _UP
        self._cache: dict[float, float] = {}
        self._shaped: dict[float, tuple[np.ndarray, float]] = {}

    @property
    def active(self) -> bool:
        """Whether any bound ``m_j`` is > 0 (else ``R = 0``)."""
        return self.q > 0

    def _integral(self, nX: float, nXh: float, eY: float, nZ: float, h: float) -> float:
        """``>= int_0^h ||e^{A_b r} X|| dr`` from ``||X||``, ``||fl(X + h Y)||`` (its rounding
        included), the error ``eY`` of ``Y`` and ``||A_b^2 X||``: the smaller of the Taylor and the
        growth bounds."""
        a = self.a
        ah = a * h
        taylor = (h * (nX + nXh) / 2.0 + h * h * eY / 2.0
                  + (nZ * _cube(h) * math.exp(ah) / 6.0 if nZ > 0.0 else 0.0)) * _UP * _UP
        growth = nX * _growth(a, h) * _UP * _UP
        return _least(taylor, growth)

    def radius(self, dt: float) -> float:
        """``R(dt)`` (balanced units) for a step of length ``dt >= 0``: the scaled pair's (:func:`_back`).
        ``R`` grows with ``dt``: a step below ``2^-1022`` is taken as ``2^-1022``, so ``h`` and ``h`` times
        the scaled norms (about 1) do not underflow."""
        if self.q == 0 or not dt > 0.0:
            return 0.0
        r = self._cache.get(dt)
        if r is not None:
            return r
        h = max(dt, NORMAL) * (1.0 + 2.0 * _U)
        g2 = gamma(2)
        if not (math.isfinite(h) and self.a * h <= 700.0):
            return math.inf
        XhY = self._B + h * self._Y
        # per column
        per = 0.0
        for j in range(self.q):
            nxh = _norm_up(XhY[:, j]) + g2 * (self._nb[j] + h * _norm_up(self._Y[:, j])) * _UP
            per += self._m[j] * self._integral(self._nb[j], nxh, self._ey[j], self._nz[j], h) * _UP
        # joint
        mxh = _mat_norm_up(XhY) + g2 * (self._mB + h * _mat_norm_up(self._Y)) * _UP
        joint = self._mnorm * self._integral(self._mB, mxh, self._meY, self._mZ, h) * _UP
        a, ah = self.a, self.a * h
        gram = (h * self._gB + h * h * self._gY / 2.0 + self._gZ * _cube(h) * math.exp(ah) / 6.0) * _UP * _UP
        gram = _least(gram, self._gB * _growth(a, h) * _UP * _UP)
        r = _back(_least(per, joint, gram) + self._lost_b(h), self._k, self.q)
        if len(self._cache) >= _CACHE:
            self._cache.clear()
        self._cache[dt] = r
        return r


    def _lost_b(self, h: float) -> float:
        """``>= sqrt(n q) eta ||m|| (e^{a h} - 1) / a`` (0 where the scaling of ``B_b`` is exact): the
        reach of its rounding (``__init__``), scaled units, rounded up (``+ eta`` where it is subnormal)."""
        if not self._eB:
            return 0.0
        return self._eB * self._mnorm * _growth(self.a, h) * _UP * UNDERFLOW * _UP + UNDERFLOW

    def shaped(self, dt: float) -> tuple[np.ndarray, float]:
        """``(G, r)``: ``d(dt)`` lies in ``E(G G')`` plus the ball of radius ``r`` (balanced units;
        module docstring). With ``wbar = (1/h) int w`` and ``wtil = (2/h^2) int_0^h r w(h - r) dr``,
        both in the box, ``d = h B_w wbar + (h^2/2) A B_w wtil + int R(r) B_w w``: the first two lie in
        ``E(q (1 + a) G1 G1') + E(q (1 + 1/a) G2 G2')`` (``G1 = h B_w diag(m)``, ``G2 = (h^2/2) A B_w
        diag(m)``, ``a`` from their balanced traces), so ``G = [sqrt(q (1 + a)) G1, sqrt(q (1 + 1/a)) G2]``;
        the remainder, ``Y``'s rounding and ``G``'s own (relative ``8 u``, the step's ``u dt`` included)
        are the ball. For ``a h > 1`` (a long step) ``G`` is empty and ``r`` is :meth:`radius`."""
        n = self._B.shape[0]
        if self.q == 0 or not dt > 0.0:
            return np.zeros((n, 0)), 0.0
        hit = self._shaped.get(dt)
        if hit is not None:
            return hit
        h = dt * (1.0 + 2.0 * _U)
        if not (math.isfinite(h) and self.a * h <= 1.0):
            return np.zeros((n, 0)), self.radius(dt)
        G, r = self._shape(dt, h)
        if not (r <= math.inf and np.all(np.isfinite(G))):
            G, r = np.zeros((n, 0)), self.radius(dt)
        G.setflags(write=False)
        if len(self._shaped) >= _CACHE:
            self._shaped.clear()
        self._shaped[dt] = (G, r)
        return G, r


    def _shape(self, dt: float, h: float) -> tuple[np.ndarray, float]:
        """:meth:`shaped`'s ``(G, r)`` for ``a h <= 1``. ``G1``, ``G2`` and the factors are formed from the
        scaled pair (B_b, m), then scaled back to the user's units by ``2^k D`` (one rounding, exact in the
        normal range). Where a result falls under ``2^-1022`` it errs by at most ``eta / 2``. In the scaled
        units (the box's vertices weigh each column by at most 1): the factors ``dt m_j`` (one rounding)
        and ``dt^2 m_j / 2`` (three, ``m_j <= 1``) by ``eta / 2`` and ``2 eta``, times ``||b_j||`` and
        ``||y_j||``; the products' entries ``q sqrt(n) eta / 2`` per block; the factors ``s1``, ``s2``
        ``sqrt(2 q n) eta / 2`` (the ellipsoid's unit ball): ``eta (sum_j (||b_j|| + 2 ||y_j||) + 2 q
        sqrt(n))`` in all, added to the remainder before :func:`_back`. The scaling back, ``sqrt(2 q n)
        max_i (1 / d_i) eta / 2``, in the balanced units."""
        Bs, m, q, k = self._B, self._m, self.q, self._k
        c1, c2 = dt * m, (dt * dt / 2.0) * m
        G1 = Bs * c1[None, :]
        G2 = self._Y * c2[None, :]
        t1 = _mat_fro_up(G1)
        t2 = _mat_fro_up(G2)
        a = min(max(t2 / t1, 1e-12), 1e12) if t1 > 0.0 else 1e12
        s1 = math.sqrt(q * (1.0 + a)) * (1.0 + 4.0 * _U)
        s2 = math.sqrt(q * (1.0 + 1.0 / a)) * (1.0 + 4.0 * _U)
        Gs = np.hstack([G1 * s1, G2 * s2])
        ls = 0.0
        if (min(float(c1.min()), float(c2.min())) < NORMAL or _lossy(G1, Bs, c1) or _lossy(G2, self._Y, c2)
                or _lossy(Gs, np.hstack([G1, G2]), np.full(2 * q, 1.0))):
            ls = float(np.sum(self._nb + 2.0 * self._ny)) + 2.0 * q * math.sqrt(Bs.shape[0])
            ls = ls * (1.0 + gamma(q + 2)) * _UP * UNDERFLOW * _UP + UNDERFLOW
        rem = _back(self._gZ * _cube(h) * math.exp(self.a * h) / 6.0 + h * h / 2.0 * float(m @ self._ey)
                    + self._lost_b(h) + ls, k, q)
        G = np.ldexp(Gs, k + self._e[:, None])
        back = 0.0
        if _lossy(G, Gs, np.full(2 * q, 1.0)):
            back = math.sqrt(2.0 * q * Bs.shape[0]) * float(self._id.max()) * _UP * UNDERFLOW + UNDERFLOW
        r = (rem + back + 8.0 * _U * _mat_fro_up(G * self._id[:, None])) * _UP * _UP
        return G, r


def _lossy(P: np.ndarray, X: np.ndarray, c: np.ndarray) -> bool:
    """Whether a product ``P = X diag(c)`` (or a scaling of ``X``) may have lost to underflow: an entry
    under ``2^-1022`` whose factors are nonzero."""
    return bool(np.any((np.abs(P) < NORMAL) & (X != 0.0) & (c != 0.0)[None, :]))


def _least(*v: float) -> float:
    """The least of the bounds ``v`` that are numbers (``nan``, an ``inf`` times 0, bounds nothing),
    ``inf`` without one."""
    return min((x for x in v if x == x), default=math.inf)


def _cube(h: float) -> float:
    """``h^3``, ``inf`` where it overflows."""
    return h ** 3 if h < 1e100 else math.inf


def _gram(X: np.ndarray, m: np.ndarray, gn: float) -> float:
    """``>= sqrt(m' |X'X| m)``, :class:`DisturbanceReach`'s Gram bound (the product's rounding ``gamma_n
    |X|'|X|`` added), plus what underflow hides from it: each entry of ``G`` (``n`` products, two more
    for the rounding term) loses at most ``(n + 2) eta``, the form ``m' G m`` (``q`` products a row,
    ``q`` more, two scalings) at most ``q eta (sum m + 1) + eta``: with ``s = sum m``, ``L eta`` under the
    root, ``L = (n + 2) s^2 + q (s + 1) + 1``, which adds at most ``s sqrt((n + 2) eta) + sqrt((q (s + 1)
    + 1) eta)`` (:func:`~switchobs_core.numerics.frobenius.underflow_slack`). Where ``L eta <= u v``
    (``v`` the computed form) one more unit in the form's factor covers ``L eta`` instead, and the
    smaller of the two bounds is taken (between the number without either term and the one with it)."""
    q = m.size
    aX = np.abs(X)
    G = np.abs(X.T @ X) + gn * (aX.T @ aX) * _UP
    s = float(m.sum()) * (1.0 + gamma(q + 2))
    slack = (s * underflow_slack(X.shape[0] + 2) + underflow_slack((q * (s + 1.0) + 1.0) * _UP)) * _UP
    v = float(m @ G @ m)
    g = math.sqrt(v * (1.0 + gamma(2 * q + 2)) * _UP) * _UP + slack
    loss = ((X.shape[0] + 2) * s * s + q * (s + 1.0) + 1.0) * UNDERFLOW * _UP
    if loss <= _U * v:
        g = min(g, math.sqrt(v * (1.0 + gamma(2 * q + 3)) * _UP) * _UP)
    return g


def _exponent(x: np.ndarray) -> int:
    """``k`` with ``max |x| 2^-k`` in ``[1/2, 1)`` (0 without a finite nonzero entry). An entry more
    than ``2^1021`` below the largest then falls under ``2^-1022`` and rounds (``__init__``)."""
    top = float(np.max(np.abs(x))) if x.size else 0.0
    if not math.isfinite(top) or top == 0.0:
        return 0
    return math.frexp(top)[1]


def _back(x: float, k: int, q: int) -> float:
    """``(x + 2 (q + 2) eta) 2^k`` rounded up (``inf`` for ``x`` nan), ``x`` a bound in the scaled units
    (every entry of ``B_b`` and ``m`` at most 1): a product there that falls under ``2^-1022`` loses at
    most ``eta / 2``, four a column (or for the joint and Gram bounds), each times ``m_j <= 1``; one more
    ``eta`` where the result is subnormal (``2^k`` rounds it). In the normal range the terms vanish in
    the rounding."""
    if x != x:
        return math.inf
    try:
        r = math.ldexp((x + 2.0 * (q + 2) * UNDERFLOW) * _UP, k)
    except OverflowError:
        return math.inf
    return r + UNDERFLOW if r < NORMAL else r


def _growth(a: float, h: float) -> float:
    """``(e^{a h} - 1) / a`` (``h`` for ``a = 0``), ``h`` where ``a h`` is below ``2^-1022``: a product
    there loses up to all of itself, and ``(e^x - 1) / x <= 1 + x`` is 1 up to the callers' margin."""
    ah = a * h
    return math.expm1(ah) / a if ah >= NORMAL else h


def _mat_fro_up(X: np.ndarray) -> float:
    """``>= ||X||_F`` (rounded up, plus what underflow hides:
    :func:`~switchobs_core.numerics.frobenius.sum_slack`)."""
    if not X.size:
        return 0.0
    s = float(np.sum(X * X))
    return math.sqrt(s) * (1.0 + gamma(X.size + 2)) * _UP + sum_slack(s, X.size)


def brute_force_reach(A: np.ndarray, B_w: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
    """``d(dt)`` for the piecewise-constant ``w`` (rows: equal pieces of ``[0, dt]``), integrated
    exactly piece by piece with the augmented exponential ``e^{[[A, B_w], [0, 0]] tau}`` (the
    reference of the tests and the bench's search for the worst case)."""
    n, q = B_w.shape
    K = w.shape[0]
    J = np.zeros((n + q, n + q))
    J[:n, :n], J[:n, n:] = A, B_w
    X = expm(J * (dt / K))
    F, GB = X[:n, :n], X[:n, n:]
    x = np.zeros(n)
    for k in range(K):
        x = F @ x + GB @ w[k]
    return x
