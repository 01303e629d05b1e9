"""The measurement error that a stamp error makes, bounded from the estimate and its bound.

A measurement ``y = C x(t_true)`` (e:outputs) stamped ``t = t_true - s`` with a stamp error
``|s| <= d`` (two computers' clocks that disagree by up to the declared clock tolerance) is read
by the observer as a measurement at ``t``: it carries the error

    ``w = C x(t + s) - C x(t) = C (e^{A s} - I) x(t) + C Gamma(s) B u``

(e:system over ``[t, t + s]`` with the input ``u`` held; ``Gamma(s) = int_0^s e^{A r} dr``). The
state is not known, the estimate and its error bound are: ``x = x_hat - x_tilde`` with
``||x_tilde|| <= beta`` (e:est_error). With ``a >= ||A||_2``, ``phi_1(z) = e^z - 1`` and
``phi_2(z) = e^z - 1 - z <= z^2 e^z / 2`` (the Taylor series of e:var_constants' exponential, term
by term), for every ``|s| <= d``:

    ``||w|| <= d ||C A x_hat|| + ||C|| ||x_hat|| phi_2(a d) + ||C|| beta phi_1(a d)
    + ||C|| ||B u|| d e^{a d}``

(``e^{A s} - I = A s + sum_{k >= 2} (A s)^k / k!``; the first term exactly for ``x_hat``, the
series' norm for the rest, e:submult and e:triangle). Every norm is taken in the balanced
coordinates of :mod:`switchobs_core.numerics.scaling` (``C D``, ``D^-1 A D``, ``D^-1 x``: the same
``w``, so the bound does not depend on the state's units), and the floating-point evaluation is
rounded up (``gamma`` factors of :mod:`switchobs_core.numerics.rounding` on the product
``C A x_hat``, a relative margin on the sum). The bound is a measurement error of the sample: it
joins the rounding of the innovation in the rigorous sets (:mod:`switchobs_core.bounds.rigorous`).
"""

from __future__ import annotations

import math

import numpy as np

from ..numerics.expm_bound import nu as nu2
from ..numerics.frobenius import fro_upper, underflow_slack
from ..numerics.rounding import NORMAL, UNDERFLOW, UNIT_ROUNDOFF, gamma
from ..numerics.scaling import balance, balanced

__all__ = ["StampError", "stamp_error_bound"]

_U = UNIT_ROUNDOFF


def _phi1(z: float) -> float:
    """``>= e^z - 1`` for ``z >= 0`` (``expm1`` is faithful: one ulp, here four; ``inf`` where it
    overflows)."""
    return math.expm1(z) * (1.0 + 4.0 * _U) if z < 709.0 else math.inf


def _product_up(*f: float) -> float:
    """``>= f_1 ... f_k`` (nonnegative doubles) wherever partial products fall under ``2^-1022``: the
    mantissas' product (each in ``[1/2, 1)``: no underflow, relative ``gamma_{k-1}``) times ``2^(sum of
    the exponents)``, which rounds once (absolute ``eta / 2`` under the normal range), rounded up; 0 with
    a factor 0, ``inf`` with one ``inf``."""
    if 0.0 in f:
        return 0.0
    if math.inf in f:
        return math.inf
    m, e = 1.0, 0
    for x in f:
        mx, ex = math.frexp(x)
        m, e = m * mx, e + ex
    try:
        r = math.ldexp(m * (1.0 + 2.0 * gamma(len(f))), e)
    except OverflowError:
        return math.inf
    return r + UNDERFLOW if r < NORMAL else r


class StampError:
    """The bound of the module docstring for one system ``A`` (``B`` the input matrix, None: no
    input), in the balanced coordinates ``scale`` (computed when not given).

    ``StampError(A).bound(C, x_hat, beta_d, d)``: ``beta_d`` bounds ``||D^-1 x_tilde||`` (the
    balanced error bound, as :meth:`ErrorEllipsoid.lam_scaled
    <switchobs_core.numerics.rounding.ErrorEllipsoid.lam_scaled>` gives it squared); returns an upper
    bound of ``sup_{|s| <= d} ||w(s)||``, rounding included; 0 for ``d = 0``.
    """

    def __init__(self, A: np.ndarray, B: np.ndarray | None = None, scale: np.ndarray | None = None):
        A = np.asarray(A, dtype=float)
        self.n = A.shape[0]
        self.d = balance(A) if scale is None else np.asarray(scale, dtype=float)
        self._id = 1.0 / self.d
        self.Ab = balanced(A, self.d)
        self.a = nu2(self.Ab)                       # >= ||D^-1 A D||_2, rounded up
        self.fA = fro_upper(self.Ab) * (1.0 + 2.0 * gamma(self.n))
        self.B = None if B is None or np.asarray(B).size == 0 else np.asarray(B, dtype=float) * self._id[:, None]
        self._CD: dict = {}

    def _cd(self, C: np.ndarray) -> tuple[np.ndarray, float, float, float | None]:
        """``(C D, ||C D||_2 upper, ||C D||_F upper, gamma_{2n+2} ||C D||_F ||A_b||_F)``, kept per matrix
        (the last None where a partial product of it is under ``2^-1022``)."""
        hit = self._CD.get(id(C))
        if hit is None or hit[0] is not C:
            if len(self._CD) > 256:
                self._CD.clear()
            Cb = np.asarray(C, dtype=float) * self.d[None, :]
            fC = fro_upper(Cb) * (1.0 + 2.0 * gamma(Cb.shape[1]))
            g = gamma(2 * self.n + 2) * fC
            gf = g * self.fA
            hit = self._CD[id(C)] = (C, Cb, nu2(Cb), fC, gf if min(g, gf) >= NORMAL else None)
        return hit[1], hit[2], hit[3], hit[4]

    def bound(self, C: np.ndarray, x_hat: np.ndarray, beta_d: float, d: float,
              u: np.ndarray | None = None) -> float:
        """``sup_{|s| <= d} ||C (e^{A s} - I) x + C Gamma(s) B u||`` over every ``x`` with
        ``||D^-1 (x - x_hat)|| <= beta_d`` (module docstring), rounded up."""
        if d <= 0.0:
            return 0.0
        Cb, nC, fC, gf = self._cd(C)
        xb = np.asarray(x_hat, dtype=float) * self._id
        xn = (math.sqrt(float(xb @ xb)) + underflow_slack(xb.size)) * (1.0 + 2.0 * gamma(self.n))
        cax = Cb @ (self.Ab @ xb)
        # |fl(C (A x)) - C A x| <= gamma_{2n} |C| |A| |x| entrywise (two products), in 2-norm
        # at most gamma_{2n} ||C||_F ||A||_F ||x|| (by _product_up where a partial product is subnormal)
        err = gf * xn if gf is not None else 0.0
        if not err >= NORMAL:
            err = _product_up(gamma(2 * self.n + 2), fC, self.fA, xn)
        lin = (math.sqrt(float(cax @ cax)) + underflow_slack(cax.size)) * (1.0 + 2.0 * gamma(cax.size)) + err
        z = self.a * d * (1.0 + 2.0 * _U)
        if z < NORMAL and self.a > 0.0:
            z = NORMAL      # a d <= fl(fl(a d) (1 + 2u)) + eta <= 2^-1022; phi_1, phi_2 grow with z
        bun = 0.0
        if self.B is not None and u is not None:
            bu = self.B @ np.asarray(u, dtype=float)
            bun = math.sqrt(float(bu @ bu)) + underflow_slack(bu.size)
            bun *= 1.0 + 2.0 * gamma(bu.size + self.B.shape[1])
        # the terms as formed, phi_2(z) <= z^2 e^z / 2 (sum_{k>=2} z^k / k! <= z^2 / 2 sum_j z^j / j!)
        # rounded up, each 0 with a zero factor (exactly, whatever another factor's overflow). Where a
        # partial product falls under 2^-1022 a later factor may magnify its loss: _product_up forms
        # the terms then (the partials checked are the least of each term's: e^z >= 1, phi_1(z) >= z)
        ez = math.exp(z) if z < 709.0 else math.inf
        has1 = z > 0.0 < nC
        has2, has3 = has1 and beta_d > 0.0, nC > 0.0 < bun
        q, nx, nb, ni = 0.5 * z * z, nC * xn, nC * beta_d, nC * bun
        nid = ni * d
        t0 = d * lin
        t1 = nx * (q * ez * (1.0 + 8.0 * _U)) if has1 else 0.0
        t2 = nb * _phi1(z) if has2 else 0.0
        if min(t0, min(q, nx, t1) if has1 else NORMAL, min(nb, t2) if has2 else NORMAL,
               min(ni, nid) if has3 else NORMAL) >= NORMAL:
            w = t0 + t1 + t2
            if has3:
                w += nid * ez * (1.0 + 4.0 * _U)
        else:
            w = (_product_up(d, lin) + _product_up(nC, xn, 0.5, z, z, ez) * (1.0 + 8.0 * _U)
                 + _product_up(nC, beta_d, _phi1(z)) + _product_up(nC, bun, d, ez) * (1.0 + 4.0 * _U))
        return w * (1.0 + 16.0 * _U)


def stamp_error_bound(A: np.ndarray, C: np.ndarray, x_hat: np.ndarray, beta: float, d: float) -> float:
    """The bound of :class:`StampError` in the user's coordinates with ``||x_tilde||_2 <= beta``
    (no balancing: ``D = I``), for one use."""
    n = np.asarray(A).shape[0]
    return StampError(A, scale=np.ones(n)).bound(C, x_hat, beta, d)
