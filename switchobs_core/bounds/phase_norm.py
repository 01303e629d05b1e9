r"""A scalar bound of the estimate's error in a norm fixed per phase of a gain table, its constants
proved in floating point.

On a gain table's grid the error maps ``M_j`` of the samples repeat with the phase ``j`` (a Kalman
sample's ``(I - K H) e^{A dt}``, :mod:`switchobs_core.bounds.kalman_map`), so a norm
``||e||_{P_j} = sqrt(e' P_j^-1 e)`` can be fixed per phase offline, with three constants:

* ``c_j`` with ``M_j P_{j-1} M_j' <= c_j^2 P_j`` (the PSD order): ``||M_j e||_{P_j} <= c_j ||e||_{P_{j-1}}``;
* ``h_j`` with ``D^2 <= h_j^2 P_j``: a residual ``||D^-1 r|| <= rho`` (the balanced norm of
  :mod:`switchobs_core.numerics.rounding`) has ``||r||_{P_j} <= h_j rho``;
* ``t_j >= lambda_max(P_j)``: ``||e|| <= sqrt(t_j) ||e||_{P_j}``, and ``b_j >= lambda_max(D^-1 P_j
  D^-1)``: ``||D^-1 e|| <= sqrt(b_j) ||e||_{P_j}`` (the residuals' ``||e||``).

Then the error ``e_k = M_j e_{k-1} + r_k`` (rounding.py, step 2) obeys ``||e_k||_{P_j} <= beta_k`` with
the scalar recursion ``beta_k = c_j beta_{k-1} + h_j rho_k`` (rounded up), and an ellipsoid
``{e : e' S^-1 e <= 1}`` enters it as ``beta = sqrt(b)`` with ``S <= b P_j``: O(1) per sample after
the residual's norms, where the ellipsoid's step costs ``M S M'`` and its allowances.

The shapes ``P_j`` may be any symmetric positive definite matrices (the constants are proved for
the ones given); :func:`lyapunov_shapes` gives the discounted periodic Lyapunov solution
``P_j = M_j P_{j-1} M_j' / lambda^2 + D^2``, for which ``c_j < lambda``.

Proof of ``X = a P - M Q M' >= 0`` (:func:`dominates`; ``P``, ``Q`` exactly symmetric, ``M`` None
for the identity), after the exact congruence with powers of two that brings the diagonals of ``P``
and ``Q`` near 1. In floating point with the standard model (``gamma_m``, rounding.py, step 4):
``Z~ = fl(fl(M Q) M')`` has ``|Z~ - M Q M'| <= gamma_{2n} |M| |Q| |M'|``; ``Z_s = fl((Z~ + Z~') / 2)``
adds ``u |Z~ + Z~'| / 2``; ``T~ = fl(fl(a P) - Z_s)`` adds ``gamma_2 (a |P| + |Z_s|)``. So ``X = T~ + E``
with ``E`` symmetric and ``|E| <= F`` entrywise (the sum of those terms), and for every ``x``:
``x' E x >= -sum_ij |E_ij| (x_i^2 + x_j^2) / 2 = -sum_i x_i^2 r_i`` with ``r_i = sum_j F_ij``
(computed with nonnegative terms only and rounded up by ``1 + 4 gamma_{3n+8}``): ``X >= T~ - diag(r)``.
``A~ = fl(T~ - diag(r'))`` with ``r' = fl(r + 2 u (|t_ii| + r) (1 + 16 u))`` differs from ``T~ -
diag(r')`` only on the diagonal, by at most ``u (|t_ii| + r'_i)``, which the added term covers
after its own sum's rounding (``u (r + 2 u (...))``): so ``A~ > 0``
(Rump's test, :func:`~switchobs_core.bounds.read.positive_definite`) proves ``X > 0``. Underflow: ``n
(n + 4) eta`` more per entry of ``r`` (rounding.py, step 8).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.linalg

from ..numerics.rounding import UNDERFLOW, UNIT_ROUNDOFF, gamma
from .read import positive_definite, verified_lambda_max

__all__ = ["PhaseNorms", "dominates", "lyapunov_shapes", "verified_factor"]

_U = UNIT_ROUNDOFF
#: The candidates' relative margins over the floating-point generalised eigenvalue, tried in turn.
_MARGINS = (1e-6, 1e-3, 3e-2, 0.3)


def dominates(a: float, P: np.ndarray, Q: np.ndarray, M: np.ndarray | None = None) -> bool:
    """Whether ``a P - M Q M' >= 0`` (PSD order; ``M`` None: ``a P - Q``) is proved in floating point
    (module docstring). ``P`` and ``Q`` must be exactly symmetric (False otherwise)."""
    P = np.asarray(P, dtype=float)
    Q = np.asarray(Q, dtype=float)
    n = P.shape[0]
    if not (a >= 0.0 and math.isfinite(a)) or not np.array_equal(P, P.T) or not np.array_equal(Q, Q.T):
        return False
    # the congruence W (.) W with W = diag(w), powers of two near diag(P)^-1/2 (exact): the same
    # order, better conditioned for the test (Q and M alike: W M V^-1, V Q V)
    w = _pow2_scale(P)
    v = w if M is None else _pow2_scale(Q)      # the identity stays the identity under W (.) W
    Ps, Qs = P * np.outer(w, w), Q * np.outer(v, v)
    Mw = None if M is None else np.asarray(M, dtype=float) * w[:, None]
    Ms = None if M is None else Mw / v[None, :]
    # a scaling by powers of two is exact when its result is normal or zero: otherwise unscaled
    if all(_normal(X) for X in (Ps, Qs, Mw, Ms) if X is not None):
        P, Q, M = Ps, Qs, Ms
    if M is None:
        Z = Q.copy()
        F = np.zeros((n, n))
    else:
        M = np.asarray(M, dtype=float)
        Z = (M @ Q) @ M.T
        aM = np.abs(M)
        F = gamma(2 * Q.shape[0]) * ((aM @ np.abs(Q)) @ aM.T)
    Zs = Z + Z.T
    Zs *= 0.5
    F += _U * 0.5 * (np.abs(Z) + np.abs(Z.T))
    T = a * P
    T -= Zs
    F += gamma(2) * (a * np.abs(P) + np.abs(Zs))
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(F))):
        return False
    r = F.sum(axis=1) * (1.0 + 4.0 * gamma(3 * n + 8)) + n * (n + 4) * UNDERFLOW
    td = np.abs(np.diagonal(T))
    r += 2.0 * _U * (td + r) * (1.0 + 16.0 * _U)
    T[np.arange(n), np.arange(n)] -= r
    return positive_definite(T)


def _normal(X: np.ndarray) -> bool:
    """Every entry finite and zero or normal (no entry in the subnormal range)."""
    a = np.abs(X)
    return bool(np.all(np.isfinite(a)) and not np.any((a > 0.0) & (a < np.finfo(float).tiny)))


def _pow2_scale(P: np.ndarray) -> np.ndarray:
    """Powers of two near ``diag(P)^-1/2`` (1 where the diagonal is not positive and finite)."""
    dg = np.diagonal(P)
    ok = np.isfinite(dg) & (dg > 0.0)
    e = np.zeros(dg.size)
    e[ok] = np.round(-0.5 * np.log2(dg[ok]))
    return np.ldexp(1.0, np.clip(e, -500, 500).astype(int))


def verified_factor(P: np.ndarray, Q: np.ndarray, M: np.ndarray | None = None) -> float:
    """The smallest of a few candidates ``a`` for which ``a P >= M Q M'`` is proved (:func:`dominates`):
    the floating-point generalised eigenvalue ``lambda_max(M Q M', P)`` times ``1 +`` each of
    :data:`_MARGINS`; ``inf`` when none is proved."""
    Z = Q if M is None else (M @ Q) @ M.T
    Z = 0.5 * (Z + Z.T)
    try:
        lam = float(scipy.linalg.eigh(Z, P, eigvals_only=True)[-1])
    except (np.linalg.LinAlgError, ValueError):
        return math.inf
    lam = max(lam, 0.0)
    if lam == 0.0:
        lam = float(np.abs(Z).max()) / max(float(np.diagonal(P).min()), 1e-300)
    for m in _MARGINS:
        a = lam * (1.0 + m)
        if dominates(a, P, Q, M):
            return a
    return math.inf


def lyapunov_shapes(maps: Sequence[np.ndarray], scale: np.ndarray, lam: float, rounds: int = 4) -> list[np.ndarray]:
    """``P_j = M_j P_{j-1} M_j' / lam^2 + D^2`` over the period's maps (``P_{-1}`` the last phase's),
    from ``P = D^2``, ``rounds`` times around the period; each exactly symmetric. Any ``P_j`` is
    valid for :class:`PhaseNorms`; this one makes ``c_j < lam`` when ``lam`` exceeds the
    per-step contraction of the period (the monodromy's spectral radius to the power ``1 / N``)."""
    D2 = np.diag(np.asarray(scale, dtype=float) ** 2)
    P = [D2.copy() for _ in maps]
    for _ in range(rounds):
        for j, Mj in enumerate(maps):
            Pj = (Mj @ P[j - 1]) @ Mj.T
            Pj /= lam * lam
            Pj += D2
            P[j] = 0.5 * (Pj + Pj.T)
    return P


class PhaseNorms:
    """The constants ``(c_j, h_j, t_j)`` of the module docstring for the maps ``maps[j]`` of one
    period (phase ``j`` maps the error after phase ``j - 1`` to that after phase ``j``, cyclically) and
    the shapes ``shapes[j]``, every one proved; ``scale`` the balancing ``D``.

    ``pn.start(S, j)`` the ``beta`` of an ellipsoid ``S`` after phase ``j``; ``pn.step(beta, j, rho)``
    the next ``beta`` after phase ``j`` with the residual ``rho``; ``pn.bound(beta, j)`` the bound of
    ``||e||``; ``pn.balanced(beta, j)`` that of ``||D^-1 e||``.
    """

    def __init__(self, maps: Sequence[np.ndarray], shapes: Sequence[np.ndarray], scale: np.ndarray) -> None:
        N = len(maps)
        d = np.asarray(scale, dtype=float)
        self.shapes = list(shapes)
        D2 = np.diag(d * d)
        up = 1.0 + 8.0 * _U
        self.c = np.array([math.sqrt(verified_factor(self.shapes[j], self.shapes[j - 1], maps[j])) * up
                           for j in range(N)])
        self.h = np.array([math.sqrt(verified_factor(P, D2)) * up for P in self.shapes])
        self.t = np.array([_lambda_max(P) for P in self.shapes])
        self.b = np.array([_lambda_max(P / np.outer(d, d)) for P in self.shapes])     # exact: powers of two
        self._sqrt_t = np.sqrt(self.t) * up
        self._sqrt_b = np.sqrt(self.b) * up

    def start(self, S: np.ndarray, j: int) -> float:
        """``beta >= ||e||_{P_j}`` for every ``e`` of the ellipsoid ``{e : e' S^-1 e <= 1}`` (``S`` exactly
        symmetric, positive semidefinite)."""
        return math.sqrt(verified_factor(self.shapes[j], S)) * (1.0 + 8.0 * _U)

    def step(self, beta: float, j: int, rho: float) -> float:
        """``c_j beta + h_j rho``, rounded up."""
        return float(self.c[j] * beta + self.h[j] * rho) * (1.0 + 8.0 * _U)

    def bound(self, beta: float, j: int) -> float:
        """``sqrt(t_j) beta >= ||e||``, rounded up."""
        return float(self._sqrt_t[j] * beta) * (1.0 + 4.0 * _U)

    def balanced(self, beta: float, j: int) -> float:
        """``sqrt(b_j) beta >= ||D^-1 e||`` (the ``||e||`` of a residual), rounded up."""
        return float(self._sqrt_b[j] * beta) * (1.0 + 4.0 * _U)


def _lambda_max(P: np.ndarray) -> float:
    """``>= lambda_max(P)``: a verified candidate (:func:`~switchobs_core.bounds.read.verified_lambda_max`),
    else the smallest ``a`` with ``a I >= P`` proved; ``inf`` if neither."""
    got = verified_lambda_max(P)
    if got is not None:
        return got[0]
    return verified_factor(np.eye(P.shape[0]), P)
