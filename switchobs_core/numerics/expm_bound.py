"""A proven bound on the error of a computed matrix exponential (and of its ZOH integral).

``scipy.linalg.expm`` returns ``Phi~``, close to ``e^{X}``, with no bound on the difference.
:func:`certify_zoh` proves one, a posteriori, for one ``(M, dt)``: it computes its own
approximation by scaling and squaring in double precision while it carries a rigorous bound
of its own error, then measures its distance to ``Phi~``. Every step below is an inequality;
no step is a model or an estimate, and the cost is about ``m + 2 s`` products of n x n
matrices (``m`` Taylor terms, ``s`` squarings; 2-4 ms at n = 132).

Norms. ``nu(X) = sqrt(||X||_1 ||X||_inf)`` bounds ``||X||_2`` and ``|| |X| ||_2`` (``|X|`` entrywise);
for nonnegative matrices ``|| |X| |Y| ||_1 <= ||X||_1 ||Y||_1`` and likewise for ``inf``. Every
computed norm is a sum of nonnegative terms, rounded up by ``(1 + gamma_{n+2})`` (sums of nonnegative
doubles do not underflow); ``sqrt(a b)`` of two of them is taken so that it does not either, where
``a b`` falls below the normal range (:func:`_sqrt_prod`).

Argument, for ``X = M dt`` (``M`` and ``dt`` the doubles given; the caller passes ``M`` in the
coordinates it wants the bound in, e.g. balanced ones, :mod:`switchobs_core.numerics.scaling`):

1. Scaling. ``h = dt 2^-s`` is exact (a power of two), ``s`` the least with ``nu(M) h <= 1/4``.
   ``Y = fl(M h)`` has ``|Y - M h| <= u |M| h``, so ``||Y - M h||_2 <= u nu(M) h =: a``.
2. Taylor. ``T_0 = I``, ``T_k = fl(fl(T_{k-1} Y) / k)``: with ``tau_k = Y^k / k!`` and
   ``eps_k >= ||T_k - tau_k||_2``: ``eps_k <= (eps_{k-1} nu(Y) + gamma_n nu(T_{k-1}) nu(Y)) / k
   + u nu(T_k)`` (the product's rounding ``|fl(A B) - A B| <= gamma_n |A| |B|``, the division's
   ``u |T_k|``). ``E_0 = fl(sum_k T_k)`` in order: ``|E_0 - sum T_k| <= gamma_m sum |T_k|``. The
   tail ``||sum_{k>m} Y^k / k!||_2 <= y^{m+1} / (m+1)! / (1 - y / (m+2))`` (``y = nu(Y)``); ``m``
   is the least with the tail below ``u / 8``. The argument's rounding:
   ``||e^Y - e^{M h}||_2 <= a e^{y + a}`` (Frechet derivative of ``exp`` bounded by ``e^{||.||}``).
   So ``||E_0 - e^{M h}||_2 <= delta_0`` with ``delta_0`` the sum of these.
3. ``Gamma(h) = int_0^h e^{M r} dr = h sum_k (M h)^k / (k+1)!``: ``G_0 = fl(h fl(sum_k T_k / (k+1)))``
   with the same terms: ``g_0`` adds their errors ``eps_k / (k+1)``, the sum's and the scalings'
   rounding (``gamma_{m+3}``), the tail ``h y^{m+1} / (m+2)! / (1 - y / (m+3))`` and ``h a e^{y + a}``.
4. Squaring. ``F_j = e^{M h 2^j}``; ``E_{j+1} = fl(E_j E_j)``: ``E^2 - F^2 = E (E - F) + (E - F) F``,
   so ``delta_{j+1} <= delta_j (2 nu(E_j) + delta_j) + gamma_n ||E_j||_1 ||E_j||_inf``.
   ``Gamma(2 t) = e^{M t} Gamma(t) + Gamma(t)``: ``G_{j+1} = fl(fl(E_j G_j) + G_j)`` and
   ``g_{j+1} <= g_j (nu(E_j) + delta_j + 1) + delta_j nu(G_j) + gamma_{n+1} nu(|E_j| |G_j| + |G_j|)``.
5. The given ``Phi~`` (and ``Gamma~``): ``||Phi~ - e^X||_2 <= nu(fl(Phi~ - E_s)) (1 + 2 gamma_{n+2})
   + delta_s`` (the difference is rounded relative ``u`` entrywise, within the allowance).

The bookkeeping itself is done in floating point with each bound inflated by a relative
``8 u`` per line, so the computed bounds are upper bounds of the quantities above.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .rounding import NORMAL, UNDERFLOW, UNIT_ROUNDOFF, gamma

__all__ = ["nu", "CertifiedStep", "certify_zoh", "expm_error_bound"]

_U = UNIT_ROUNDOFF
#: Largest ``nu(M h)`` of the scaled argument (step 1).
THETA = 0.25
#: Most Taylor terms (step 2 stops before: ``0.25^18 / 18! < 1e-26``).
MAX_TERMS = 18
_UP = 1.0 + 8.0 * _U      # each line of bookkeeping rounded up


def _nu1inf(X: np.ndarray) -> tuple[float, float]:
    """``(||X||_1, ||X||_inf)`` rounded up (sums of nonnegative terms)."""
    if X.size == 0:
        return 0.0, 0.0
    A = np.abs(X)
    f = 1.0 + 2.0 * gamma(max(X.shape) + 2)
    return float(A.sum(axis=0).max()) * f, float(A.sum(axis=1).max()) * f


def _sqrt_prod(a: float, b: float) -> float:
    """``>= sqrt(a b)`` for ``a, b >= 0``, also where ``a b`` underflows (below ``~1e-162`` each, a
    product under the normal range loses up to ``eta / 2`` and is 0 below ``eta``): there
    ``sqrt(a) sqrt(b)``, each factor normal (``sqrt(eta) = 2^-537``), plus ``2 eta`` for the product's
    absolute rounding and the factors' relative ``2 u`` of a result below ``2^-1022`` (``eta``,
    :data:`~switchobs_core.numerics.rounding.UNDERFLOW`). In the normal range ``sqrt(a b)`` rounded up."""
    p = a * b
    if p >= NORMAL or not p == p or a == 0.0 or b == 0.0:
        return math.sqrt(p) * _UP
    return math.sqrt(a) * math.sqrt(b) * _UP + 2.0 * UNDERFLOW


def nu(X: np.ndarray) -> float:
    """``sqrt(||X||_1 ||X||_inf) >= ||X||_2`` (and ``>= || |X| ||_2``), rounded up (:func:`_sqrt_prod`:
    also where the product of the two norms underflows)."""
    a, b = _nu1inf(X)
    return _sqrt_prod(a, b)


class CertifiedStep(NamedTuple):
    """``E ~ e^{M dt}`` with ``||E - e^{M dt}||_2 <= dE``, and ``G ~ Gamma(dt)`` with ``dG`` (None
    when not asked for)."""

    E: np.ndarray
    dE: float
    G: np.ndarray | None
    dG: float


def certify_zoh(M: np.ndarray, dt: float, gamma_too: bool = False) -> CertifiedStep:
    """The approximation of steps 1-4 of the module docstring with its proven error bounds
    (``inf`` when the arithmetic overflows)."""
    M = np.asarray(M, dtype=float)
    n = M.shape[0]
    dt = float(dt)
    I = np.eye(n)
    if n == 0 or dt == 0.0:
        return CertifiedStep(I, 0.0, np.zeros((n, n)) if gamma_too else None, 0.0)
    nM = nu(M)
    if not math.isfinite(nM):
        return CertifiedStep(I, math.inf, None, math.inf)
    s = 0
    if nM * dt > THETA:
        s = max(0, math.ceil(math.log2(nM * dt / THETA)))
        while nM * math.ldexp(dt, -s) > THETA:
            s += 1
    h = math.ldexp(dt, -s)
    Y = M * h
    y = nu(Y)
    a = _U * nM * h * _UP
    gn, gn1 = gamma(n), gamma(n + 1)
    # 2. Taylor terms with their errors (eps_k), the sum of the terms and of the terms / (k + 1)
    T = I
    E = I.copy()
    G = I.copy() if gamma_too else None
    eps, sum_eps, sum_eps_g, sum_nT, sum_nT_g = 0.0, 0.0, 0.0, 1.0, 1.0
    nT = 1.0
    m = 0
    fact = 1.0
    for k in range(1, MAX_TERMS + 1):
        Tn = (T @ Y) / k
        nTn = nu(Tn)
        eps = ((eps * y + gn * nT * y) / k + _U * nTn) * _UP
        T, nT = Tn, nTn
        sum_eps += eps
        E += T
        sum_nT += nT
        if G is not None:
            G += T / (k + 1)
            sum_eps_g += eps / (k + 1)
            sum_nT_g += nT / (k + 1)
        m = k
        fact *= k + 1                         # (m + 1)!
        tail = y ** (m + 1) / fact / (1.0 - y / (m + 2))
        if tail <= _U / 8:
            break
    # tail, the sum's rounding, the terms' errors and the argument's rounding
    arg = a * math.exp(y + a)
    delta = (tail + gamma(m + 1) * sum_nT + sum_eps + arg) * _UP
    dG = 0.0
    if G is not None:
        G *= h
        tail_g = h * y ** (m + 1) / (fact * (m + 2)) / (1.0 - y / (m + 3))
        dG = (tail_g + h * (gamma(m + 3) * sum_nT_g + sum_eps_g + arg)) * _UP
    # 4. squarings
    for _ in range(s):
        e1, einf = _nu1inf(E)
        nE = _sqrt_prod(e1, einf)
        if G is not None:
            g1, ginf = _nu1inf(G)
            nG = _sqrt_prod(g1, ginf)
            rnd = _sqrt_prod(e1 * g1 + g1, einf * ginf + ginf)
            dG = (dG * (nE + delta + 1.0) + delta * nG + gn1 * rnd) * _UP
            G = E @ G + G
        delta = (delta * (2.0 * nE + delta) + gn * e1 * einf) * _UP
        E = E @ E
        if not math.isfinite(delta):
            break
    if not (math.isfinite(delta) and np.all(np.isfinite(E))):
        delta = dG = math.inf
    if G is not None and not np.all(np.isfinite(G)):
        dG = math.inf
    return CertifiedStep(E, delta, G, dG)


def expm_error_bound(approx: np.ndarray, ref: np.ndarray, d_ref: float) -> float:
    """``>= ||approx - exact||_2`` from a reference ``ref`` with ``||ref - exact||_2 <= d_ref``
    (step 5 of the module docstring)."""
    diff = approx - ref
    return (nu(diff) * (1.0 + 2.0 * gamma(diff.shape[0] + 2)) + d_ref) * _UP if math.isfinite(d_ref) else math.inf
