"""The observer's rigorous error bounds in floating point: the exact one and the noise one.

One owner of the two ellipsoids the observer keeps (the argument is in
:mod:`switchobs_core.numerics.rounding`, steps 1-7):

* the *exact bound*: ``{e : e' S^-1 e <= 1}`` holds the error of the computed estimate for
  noise-free samples, ``S_0 = e0^2 I``, each step ``e <- M e + r`` with the step's error map
  ``M`` and a residual ``||r|| <= rho`` (the matrix exponential's error, the step quantum and
  the rounding of the products, :meth:`RoundingBound.rho_step`, :meth:`RoundingBound.rho_correct`);
* the *noise bound* (a declared ``|v_j| <= v_max``): the same with the noise's image ``G v`` added
  to every step (``G = Gamma_A L`` for the held innovation of LMI gains, ``G = K`` for a Kalman
  correction), the degenerate ellipsoid ``E(p v_max^2 G G')``.

The observer steps it with the error maps of every sample
(:mod:`switchobs_core.runtime.error_maps`): :meth:`RoundingBound.step` for a propagation step,
:meth:`RoundingBound.correct` for a Kalman correction, :meth:`RoundingBound.fused` for both in one
map, :meth:`RoundingBound.hold` for a held innovation; :meth:`RoundingBound.propagated` gives the
sets at a later time without keeping them (``prior``, ``envelope``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid, gamma
from .read import AnchoredBound

__all__ = ["RoundingBound"]


class RoundingBound:
    """Both ellipsoids of the module docstring for a system ``A`` with outputs of at most ``p_max`` rows.

    ``b = RoundingBound(A, p_max, e0, noise_max)``; ``b.reset()`` restarts at ``S = e0^2 I``.
    ``noise_max`` is one bound per channel (None: no noise ellipsoid).
    """

    def __init__(self, A: np.ndarray, p_max: int, e0: float, noise_max: Sequence[float] | None) -> None:
        self.n = A.shape[0]
        self.e0 = e0
        self.noise_max = noise_max
        # constants: ||A||_F, ||A||_2 (step quantum), gamma_{n+2}, gamma_{p+2}
        self.fA = float(np.linalg.norm(A))
        self.nA = float(np.linalg.norm(A, 2))
        self.g_n = gamma(self.n + 2)
        self.g_p = gamma(p_max + 2)
        self.reset()

    def reset(self) -> None:
        """``S = e0^2 I`` for both ellipsoids; nothing held."""
        self.ell = ErrorEllipsoid(self.n, self.e0)
        self.ellv = ErrorEllipsoid(self.n, self.e0) if self.noise_max else None
        self._read, self._readv = AnchoredBound(), AnchoredBound()     # the published bounds
        self.vn = 0.0       # sqrt(p) v_max of the held sample (the noise's largest norm)
        self.nu_err = 0.0   # rounding of the held innovation nu = y - C x_hat (and of y itself)

    # ------------------------------------------------------------------ residuals
    def hold(self, C: np.ndarray, xn: float, y: np.ndarray, channel: int, p: int) -> None:
        """A held innovation ``nu = y - C x_hat`` (LMI gains): its rounding, and its noise's norm."""
        self.nu_err = self.g_n * float(np.linalg.norm(C)) * xn + 2.0 * UNIT_ROUNDOFF * math.sqrt(float(y @ y))
        if self.ellv is not None:
            self.vn = math.sqrt(p) * self.noise_max[channel - 1]

    def rho_step(self, e: Any, dt: float, xn: float, xn_new: float, ell: ErrorEllipsoid,
                 nu: np.ndarray | None, u: np.ndarray | None) -> float:
        """Residual bound ``rho`` of one exact step in floating point
        (:mod:`switchobs_core.numerics.rounding`, steps 2-4):
        the exponential's error and the step quantum, times ``||x|| <= ||x_hat|| + ||e||``
        (``||e||`` from ``ell``, the ellipsoid being stepped), plus the rounding of the products.
        ``nu``: the held innovation (None: no gain held); ``u``: the held input (None: zero)."""
        quant = abs(dt - e.dt) * self.fA * math.exp(min(self.nA * max(dt, e.dt), 700.0))   # no OverflowError
        rho = (e.eps + quant) * (xn + ell.trace_bound()) + self.g_n * e.fPhi * xn + UNIT_ROUNDOFF * xn_new
        if nu is not None:
            nun = math.sqrt(float(nu @ nu))
            rho += self.g_p * e.fGL * nun + e.fGL * self.nu_err
        if u is not None:
            un = math.sqrt(float(u @ u))
            rho += (e.eps + self.g_n * float(np.linalg.norm(e.GB))) * un
        return rho

    def rho_correct(self, fK: float, fH: float, xn_minus: float, yn: float, nun: float, xn_plus: float) -> float:
        """Residual bound of a Kalman correction ``x^+ = x^- + K (y - H x^-)`` in floating point
        (products ``H x^-`` and ``K nu``, the two sums, and the data's own rounding ``u ||y||``)."""
        u = UNIT_ROUNDOFF
        return fK * (self.g_n * fH * xn_minus + 2.0 * u * yn) + self.g_p * fK * nun + u * xn_plus

    # ------------------------------------------------------------------ steps
    def _noise(self, ell: ErrorEllipsoid, E: np.ndarray, rho: float, GL: np.ndarray | None,
               keep: bool) -> tuple | None:
        """A step of the noise ellipsoid: the held innovation's noise enters through ``Gamma L``
        (``||v||^2 <= p v_max^2``); open-loop steps and Kalman prediction steps add none."""
        if GL is not None and self.vn > 0.0:
            if keep:
                ell.step_shaped(E, rho, GL, self.vn ** 2)
                return None
            return ell.propagate_shaped(E, rho, GL, self.vn ** 2)
        if keep:
            ell.step(E, rho)
            return None
        return ell.propagate(E, rho)

    def step(self, e: Any, dt: float, xn: float, xn_new: float, nu: np.ndarray | None,
             u: np.ndarray | None, extra: float = 0.0) -> None:
        """Both ellipsoids through one propagation step ``e`` (a ZOH cache entry) over ``dt``;
        ``extra``: the residual of what the step added besides (an input changed within it)."""
        self.ell.step(e.E, self.rho_step(e, dt, xn, xn_new, self.ell, nu, u) + extra)
        if self.ellv is not None:
            self._noise(self.ellv, e.E, self.rho_step(e, dt, xn, xn_new, self.ellv, nu, u) + extra,
                        e.GL if nu is not None else None, True)

    def propagated(self, e: Any, dt: float, xn: float, xpn: float, nu: np.ndarray | None,
                   u: np.ndarray | None, extra: float = 0.0) -> tuple[np.ndarray, np.ndarray | None]:
        """The shape matrices after the step ``e`` over ``dt``, not kept: ``(S, S_noise or None)``
        (``extra`` as in :meth:`step`)."""
        S, _ = self.ell.propagate(e.E, self.rho_step(e, dt, xn, xpn, self.ell, nu, u) + extra)
        Sv = None
        if self.ellv is not None:
            Sv, _ = self._noise(self.ellv, e.E, self.rho_step(e, dt, xn, xpn, self.ellv, nu, u) + extra,
                                e.GL if nu is not None else None, False)
        return S, Sv

    def correct(self, M: np.ndarray, rho: float, K: np.ndarray, p: int, channel: int) -> None:
        """Both ellipsoids through a Kalman correction ``e^+ = M e^- + r + K v`` (``M = I - K H``)."""
        self.ell.step(M, rho)
        if self.ellv is not None:      # e^+ = (I - K H) e^- + K v
            self.ellv.step_shaped(M, rho, K, p * self.noise_max[channel - 1] ** 2)

    def fused(self, e: Any, dt: float, m: Any, x0n: float, xmn: float, rc: float,
              K: np.ndarray, p: int, channel: int, u: np.ndarray | None = None) -> None:
        """Both ellipsoids through a Kalman sample's fused map ``M = (I - K H) e^{A dt}``
        (a :class:`~switchobs_core.bounds.kalman_map.KalmanMap`: ``M S M'`` dense or factored, with its
        rounding allowance): the prediction's residual (input ``u`` held, None: zero) through
        ``||I - K H||_2`` plus the correction's ``rc``."""
        ell = self.ell
        Z, eta = m.sandwich(ell.S, ell.tr, ell.g_dense)
        ell.S, ell.tr = ell.propagate_product(Z, eta, m.nIKH * self.rho_step(e, dt, x0n, xmn, ell, None, u) + rc)
        ellv = self.ellv
        if ellv is not None:      # e^+ = (I - K H) e^- + K v
            Z, eta = m.sandwich(ellv.S, ellv.tr, ellv.g_dense)
            ellv.S, ellv.tr = ellv.propagate_shaped_product(
                Z, eta, m.nIKH * self.rho_step(e, dt, x0n, xmn, ellv, None, u) + rc, K,
                p * self.noise_max[channel - 1] ** 2)

    # ------------------------------------------------------------------ bounds
    def bounds(self, S: np.ndarray | None = None, Sv: np.ndarray | None = None, *,
               amortised: bool = False) -> tuple[float, float | None]:
        """``(exact, noise)``: upper bounds of ``sqrt(lambda_max)`` of the shape matrices (default
        the current ones): the eigenvalue problem's, or with ``amortised`` (current sets only)
        :mod:`switchobs_core.bounds.read`'s (a verified upper bound per anchor, O(n^2) in between, at most 1.062x
        larger)."""
        if amortised and S is None and Sv is None:
            return self._read.read(self.ell), None if self.ellv is None else self._readv.read(self.ellv)
        exact = self.ell.bound(S)
        noisy = None if self.ellv is None else self.ellv.bound(Sv)
        return exact, noisy
