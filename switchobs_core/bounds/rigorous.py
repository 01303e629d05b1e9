"""The observer's rigorous error bounds in floating point: the exact one and the noise one.

One owner of the two ellipsoids the observer keeps (the argument is in
:mod:`switchobs_core.numerics.rounding`, steps 1-7):

* the *exact bound*: ``{e : e' S^-1 e <= 1}`` holds the error of the computed estimate for
  noise-free samples, ``S_0 = e0^2 I``, each step ``e <- M e + r`` with the step's error map
  ``M`` and a residual ``||D^-1 r|| <= rho`` in the balanced coordinates of ``A``
  (:mod:`switchobs_core.numerics.scaling`: every norm of a residual is taken there, so the bound
  does not depend on the units of the state): the matrix exponential's proven error, the step
  quantum and the rounding of the products and of the stored maps
  (:meth:`RoundingBound.rho_step`, :meth:`RoundingBound.rho_correct`);
* the *noise bound* (a declared ``|v_j| <= v_max``): the same with the noise's image ``G v`` added
  to every step (``G = Gamma_A L`` for the held innovation of LMI gains, ``G = K`` for a Kalman
  correction), the degenerate ellipsoid ``E(p v_max^2 G G')``; and with a declared disturbance
  (``x' = A x + B_w w``, ``|w_j| <= max_j``, :mod:`switchobs_core.model.disturbance`) the ball of
  its reachable set over every step, ``||D^-1 d(dt)|| <= R(dt)``
  (:class:`~switchobs_core.numerics.disturbance_reach.DisturbanceReach`): the degenerate ellipsoid
  ``E(G_d G_d')`` of its first-order part joined to the noise's shaped term and the ball of its
  second-order part joined to the step's residual (:meth:`RoundingBound.disturbed`, a term of its
  own). The exact bound stays the model's (noise-free samples, no disturbance);
* a declared clock tolerance ``d`` (:meth:`RoundingBound.clock`: the largest error of a sample's
  stamp): each sample carries a measurement error of at most ``w`` of
  :class:`~switchobs_core.bounds.stamp.StampError`, bounded from the estimate and the sets' own
  bound before the sample (their largest axis in balanced units), which enters both sets through
  the gain as the noise does (the degenerate ellipsoid ``E(w^2 G G')``; ``(sqrt(p) v_max + w)^2``
  in the noise set, ``||v + w|| <= ||v|| + ||w||``): neither set assumes exact stamps.

The observer steps it with the error maps of every sample
(:mod:`switchobs_core.runtime.error_maps`): :meth:`RoundingBound.step` for a propagation step,
:meth:`RoundingBound.correct` for a Kalman correction, :meth:`RoundingBound.fused` for both in one
map, :meth:`RoundingBound.hold` for a held innovation; :meth:`RoundingBound.propagated` gives the
sets at a later time without keeping them (``prior``, ``envelope``).

A bound that can no longer be computed (a set that overflowed, a shape matrix that is not
finite) is *withdrawn*: :attr:`RoundingBound.withdrawn` says why, the published bounds are
``inf`` from then on (until :meth:`RoundingBound.reset`), and no method raises: the estimate is
not touched by any of this.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..numerics import dense_kernel
from ..numerics.disturbance_reach import DisturbanceReach
from ..numerics.expm_bound import nu as nu2
from ..numerics.frobenius import SQRT_ETA, fro_upper, underflow_slack
from ..numerics.rounding import UNDERFLOW, UNIT_ROUNDOFF, ErrorEllipsoid, PendingSet, gamma
from ..numerics.scaling import balance, balanced
from .kalman_map import open_loop_product, sparse_map
from .read import AnchoredBound
from .stamp import StampError

__all__ = ["NO_E0", "RoundingBound", "open_loop_product"]     # open_loop_product: kalman_map's


#: Per entry of a scaled norm: what underflow hides from the square (``sqrt(eta)``) and the product ``s_i v_i``.
_NORM_SLACK = SQRT_ETA + UNDERFLOW


def _norm(v: np.ndarray, s: np.ndarray | None = None) -> float:
    """``||diag(s) v||`` (``s`` None: ``||v||``), by the compiled kernel where it is built and takes ``v``
    (:data:`~switchobs_core.numerics.dense_kernel.NORM`: the sum of squares in another order), else numpy;
    either plus what underflow can hide, ``sqrt(n) (sqrt(eta) + eta)``: an upper bound up to the relative
    rounding the residuals allow for."""
    slack = math.sqrt(v.size) * _NORM_SLACK
    if dense_kernel.NORM is not None:
        try:
            return dense_kernel.NORM(v, s) + slack
        except (BufferError, ValueError, TypeError):
            pass
    if s is not None:
        v = v * s
    return math.sqrt(float(v.dot(v))) + slack


#: Why the bounds are withdrawn from the start when no initial error bound is given (``e0`` None).
NO_E0 = ("e0 is not known (e0 = -1): no bound until the data certify one (a window of one switching cycle "
         "of consistent samples, switchobs_core.runtime.recertify)")

_U = UNIT_ROUNDOFF


def _whole(out: Any) -> tuple[np.ndarray, float]:
    """``(S, trace S rounded up)`` of a step's set kept whole (a copy) or pending (assembled now)."""
    if isinstance(out, PendingSet):
        return out.full().copy(), out.tr
    return out[0].copy(), out[1]


class RoundingBound:
    """Both ellipsoids of the module docstring for a system ``A`` with outputs of at most ``p_max`` rows.

    ``b = RoundingBound(A, p_max, e0, noise_max, B=B, scale=d)``; ``b.reset()`` restarts at
    ``S = e0^2 I``. ``noise_max`` is one bound per channel (None: no noise ellipsoid); ``B`` the
    input matrix (None: no input); ``disturbance`` a
    :class:`~switchobs_core.model.disturbance.Disturbance` entering the noise ellipsoid (None: none;
    needs ``noise_max``); ``scale`` the balancing of ``A``
    (:func:`~switchobs_core.numerics.scaling.balance`, computed when not given; the ZOH cache
    entries stepped here must carry the same one).
    """

    def __init__(self, A: np.ndarray, p_max: int, e0: float | None, noise_max: Sequence[float] | None, *,
                 B: np.ndarray | None = None, scale: np.ndarray | None = None, disturbance: Any = None) -> None:
        self.n = A.shape[0]
        self.e0 = e0
        self.noise_max = noise_max
        self.d = balance(A) if scale is None else np.asarray(scale, dtype=float)
        self._id = 1.0 / self.d
        self._unit = bool(np.all(self.d == 1.0))     # no scaling: ||D^-1 x|| = ||x||
        self._xlast: tuple = (None, 0.0)     # the last x^+ of a fused step and its balanced norm (the next x0's)
        # ||A||_2 in balanced coordinates (the step quantum), gamma_{n+2}, gamma_{p+2}
        self.nA = nu2(balanced(A, self.d))
        self.g_n = gamma(self.n + 2)
        self.g_p = gamma(p_max + 2)
        #: The reachable set of the declared disturbance per step (None: none declared).
        self.reach = (DisturbanceReach(A, disturbance.B_w, disturbance.w_max, self.d)
                      if disturbance is not None and disturbance.active and noise_max else None)
        self.fB = 0.0 if B is None or B.size == 0 else fro_upper(B / self.d[:, None])
        self.g_m = gamma((0 if B is None else B.shape[1]) + 2)
        self._CD: dict = {}
        self._AB = (A, B)
        #: The scalars of :class:`~switchobs_core.bounds.phase_bound.PhaseBound` (the observer's
        #: ``bound="phase"``; None: the ellipsoids only). While they hold, any use of :attr:`ell` or
        #: :attr:`ellv` first puts the ellipsoids back.
        self.phase: Any = None
        self.tolerance = 0.0            # the clock tolerance d (s; :meth:`clock`)
        self.stamp: StampError | None = None
        # underflow (rounding.py, step 8): absolute eta / 2 per product, at most n + p + m + 4 of them
        # per component of a step's result, in balanced units
        self._uf = (self.n + p_max + (0 if B is None else B.shape[1]) + 4) * UNDERFLOW * math.sqrt(
            float(self._id @ self._id))
        self.reset()

    def reset(self) -> None:
        """``S = e0^2 I`` for both ellipsoids; nothing held; the bound no longer withdrawn (with
        ``e0`` None: withdrawn until :meth:`restart`, no initial error being known)."""
        self.vn = 0.0       # sqrt(p) v_max of the held sample (the noise's largest norm)
        self.w = 0.0        # the held sample's stamp error (its measurement error's largest norm)
        self.nu_err = 0.0   # rounding of the held innovation nu = y - C x_hat (and of y itself)
        self.restart(self.e0)
        if self.e0 is None:
            self.withdrawn = NO_E0

    def restart(self, e: float | None) -> None:
        """Both ellipsoids the ball ``S = e^2 I`` from now on (a bound ``||x - x_hat|| <= e`` that holds
        now: a re-certification, :mod:`switchobs_core.runtime.recertify`); the held innovation's
        residuals are kept; the bound no longer withdrawn."""
        r = 0.0 if e is None else float(e)
        self._ell = ErrorEllipsoid(self.n, r, self.d)
        self._ellv = ErrorEllipsoid(self.n, r, self.d) if self.noise_max else None
        if self.phase is not None:
            self.phase.reset()
        self._read, self._readv = AnchoredBound(), AnchoredBound()     # the published bounds
        self._memo: tuple | None = None     # the last propagated() sets and their arguments (step reuses them)
        #: Why the bound can no longer be computed ("" while it can; module docstring).
        self.withdrawn = ""

    @property
    def ell(self) -> ErrorEllipsoid:
        """The exact set's ellipsoid (put back from the phase bound's scalar if that holds)."""
        if self.phase is not None and self.phase.j >= 0:
            self.phase.leave(self)
        return self._ell

    @property
    def ellv(self) -> ErrorEllipsoid | None:
        """The noise set's ellipsoid (None without a declared ``noise_max``; put back like :attr:`ell`)."""
        if self.phase is not None and self.phase.j >= 0:
            self.phase.leave(self)
        return self._ellv

    def clock(self, tolerance: float) -> None:
        """Declare the largest stamp error ``d`` (s) of any sample: from then on every sample's
        measurement error of :class:`~switchobs_core.bounds.stamp.StampError` enters both sets
        (0: exact stamps)."""
        self.tolerance = max(float(tolerance), 0.0)
        if self.tolerance > 0.0 and self.stamp is None:
            self.stamp = StampError(self._AB[0], self._AB[1], scale=self.d)

    def beta(self) -> float:
        """``>= ||D^-1 e||`` over both sets (the larger: one allowance serves both): the largest
        eigenvalue of ``D^-1 S D^-1``, the solver's error included
        (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.lam_upper`)."""
        scale = np.outer(self._id, self._id)
        b = self.ell.lam_upper(self.ell.S * scale)
        if self.ellv is not None:
            b = max(b, self.ellv.lam_upper(self.ellv.S * scale))
        return math.sqrt(b) * (1.0 + 2.0 * _U)

    def stamp_error(self, C: np.ndarray, x: np.ndarray, beta: float | None = None,
                    u: np.ndarray | None = None) -> float:
        """``w``: the measurement error a stamp error within the tolerance makes in a sample of
        rows ``C`` taken where the estimate is ``x`` and the balanced error at most ``beta``
        (default :meth:`beta`, the sets now); 0 without a tolerance."""
        if self.stamp is None or self.tolerance <= 0.0:
            return 0.0
        return self.stamp.bound(C, x, self.beta() if beta is None else beta, self.tolerance, u)

    # ------------------------------------------------------------------ norms in balanced units
    def xn(self, x: np.ndarray) -> float:
        """``||D^-1 x||``."""
        return _norm(x, None if self._unit else self._id)

    def fused_norms(self, x0: np.ndarray, xm: np.ndarray, xp: np.ndarray) -> tuple[float, float, float]:
        """``||D^-1 .||`` of a fused step's ``x0``, ``x^-`` and ``x^+``; ``x^+``'s is kept for the next
        step, whose ``x0`` is the same array (compared by identity: an estimate changed in place by its
        reader would move the error itself outside every set, whatever norm is taken here)."""
        xl = self._xlast
        xs = xl[1] if x0 is xl[0] else self.xn(x0)
        xsp = self.xn(xp)
        self._xlast = (xp, xsp)
        return xs, self.xn(xm), xsp

    def _cd(self, C: np.ndarray) -> float:
        """``||C D||_F`` (kept per matrix)."""
        hit = self._CD.get(id(C))
        if hit is None or hit[0] is not C:
            if len(self._CD) > 256:
                self._CD.clear()
            hit = self._CD[id(C)] = (C, fro_upper(C * self.d[None, :]))
        return hit[1]

    def gain_norms(self, K: np.ndarray, H: np.ndarray) -> tuple[float, float, float]:
        """``(||D^-1 K||_F, ||H D||_F, kappa)`` with ``kappa >= ||I - K H||_2`` balanced
        (``1 + sqrt(||.||_1 ||.||_inf)`` of ``|D^-1 K| |H D|``)."""
        Ks, Hs = K * self._id[:, None], H * self.d[None, :]
        aK, aH = np.abs(Ks), np.abs(Hs)
        one = float((aK.sum(axis=0) @ aH).max()) if aH.size else 0.0
        inf = float((aK @ aH.sum(axis=1)).max()) if aK.size else 0.0
        kappa = 1.0 + math.sqrt(one * inf) * (1.0 + 2.0 * gamma(K.shape[0] + 2 * H.shape[0] + 2))
        return fro_upper(Ks), fro_upper(Hs), kappa

    # ------------------------------------------------------------------ residuals
    def hold(self, C: np.ndarray, x: np.ndarray, y: np.ndarray, channel: int, p: int,
             u: np.ndarray | None = None) -> None:
        """A held innovation ``nu = y - C x_hat`` (LMI gains): its rounding, its noise's norm and
        its stamp error's (:meth:`stamp_error`, from the sets at the sample; ``u`` the held input)."""
        yn = math.sqrt(float(y @ y)) + underflow_slack(y.size)
        self.nu_err = self.g_n * self._cd(C) * self.xn(x) + 2.0 * _U * yn + (self.n + 2) * math.sqrt(p) * UNDERFLOW
        self.w = self.stamp_error(C, x, u=u) if self.tolerance else 0.0
        if self.ellv is not None:
            self.vn = math.sqrt(p) * self.noise_max[channel - 1]

    def rho_step(self, e: Any, dt: float, x0: np.ndarray, x1: np.ndarray, ell: ErrorEllipsoid,
                 nu: np.ndarray | None, u: np.ndarray | None) -> float:
        """Residual bound ``rho`` (balanced) of one exact step ``e`` (a ZOH cache entry) over the true
        ``dt`` in floating point (:mod:`switchobs_core.numerics.rounding`, steps 2-4): the
        exponential's proven error ``eps`` and the step quantum ``q`` times ``||x|| <= ||x_hat|| +
        ||e||`` (``||e||`` from ``ell``, the ellipsoid being stepped), the stored map's rounding
        times ``||e||``, plus the rounding of the products. ``nu``: the held innovation (None: no
        gain held); ``u``: the held input (None: zero)."""
        return self._rho_step(e, dt, self.xn(x0), self.xn(x1), math.sqrt(ell.lam_scaled()), nu, u)

    def _rho_step(self, e: Any, dt: float, xs: float, xs1: float, en: float, nu: np.ndarray | None,
                  u: np.ndarray | None) -> float:
        """:meth:`rho_step` from the norms ``xs = ||D^-1 x0||``, ``xs1 = ||D^-1 x1||`` and ``en``
        (``||D^-1 e|| <= en``), computed once for both sets."""
        # the step quantum: the true step is dt (a difference of two doubles: within u dt of it)
        delta = abs(dt - e.dt) + _U * dt
        q = (e.nPhi + e.eps) * math.expm1(self.nA * delta) * (1.0 + 4.0 * _U) if delta > 0.0 else 0.0
        rho = (e.eps + q) * (xs + en) + e.emap * en + self.g_n * e.fPhi * xs + 2.0 * _U * xs1 + self._uf
        if nu is not None:
            nun = math.sqrt(float(nu @ nu)) + underflow_slack(nu.size)
            rho += self.g_p * e.fGL * nun + e.fGL * self.nu_err
        if u is not None:
            un = math.sqrt(float(u @ u)) + underflow_slack(u.size)
            rho += (e.epsG * self.fB + self.g_m * e.fGB) * un
        return rho * (1.0 + 8.0 * _U)

    def disturbed(self, dt: float, G1: np.ndarray | None, c1: float, K: np.ndarray | None = None,
                  H: np.ndarray | None = None, nIKH: float = 1.0) -> tuple[np.ndarray | None, float, float]:
        """The noise ellipsoid's shaped term ``(G, c)`` with the disturbance of a step over ``dt``
        joined, and the ball it adds (balanced): ``(G, c, r)``. The disturbance's ``E(G_d G_d')``
        (:meth:`~switchobs_core.numerics.disturbance_reach.DisturbanceReach.shaped`; through
        ``I - K H`` for a Kalman sample's fused map, ``nIKH >= ||I - K H||`` on its ball) and the noise's
        ``E(c1 G1 G1')`` lie in ``E(G G')``, ``G = [sqrt(c1 (1 + a)) G1, sqrt(1 + 1/a) G_d]`` for any
        ``a > 0`` (``a`` balances their balanced traces; the scalings are rounded up, the products'
        rounding, relative ``u``, and that of ``(I - K H) G_d`` are in ``r``)."""
        if self.reach is None or not dt > 0.0:
            return G1, c1, 0.0
        Gd, r = self.reach.shaped(dt)
        r *= nIKH
        idc = self._id[:, None]
        if K is not None:       # (I - K H) G_d = G_d - K (H G_d), entrywise error below
            HG = H @ Gd
            KHG = K @ HG
            err = (gamma(self.n + 2) + gamma(H.shape[0] + 2) + _U) * (np.abs(K) @ (np.abs(H) @ np.abs(Gd))) \
                + _U * (np.abs(Gd) + np.abs(KHG))
            Gd = Gd - KHG
            r += 2.0 * fro_upper(err * idc)
        fd = fro_upper(Gd * idc)
        if G1 is None or not c1 > 0.0 or G1.size == 0:
            return Gd, 1.0, r * (1.0 + 8.0 * _U)
        f1 = fro_upper(G1 * idc) * math.sqrt(c1)
        a = min(max(fd / f1, 1e-8), 1e8) if f1 > 0.0 else 1e8
        s1 = math.sqrt(c1 * (1.0 + a)) * (1.0 + 4.0 * _U)
        s2 = math.sqrt(1.0 + 1.0 / a) * (1.0 + 4.0 * _U)
        G = np.hstack([G1 * s1, Gd * s2])
        r += 2.0 * _U * (f1 * s1 / math.sqrt(c1) + fd * s2)
        return G, 1.0, r * (1.0 + 8.0 * _U)

    def rho_input(self, e: Any, dt: float, d: np.ndarray, x: np.ndarray) -> float:
        """Residual bound (balanced) of adding an input change's exact ZOH to the estimate,
        ``x <- x + Gamma(dt) B d`` (:mod:`switchobs_core.runtime.held_input`), with ``e`` the ZOH
        entry of the step's key at the cached ``e.dt`` and ``dt`` the true time since the change:
        ``Gamma``'s proven error ``epsG`` and its step quantum
        ``||Gamma(dt) - Gamma(e.dt)|| <= delta (||Phi|| + eps) e^{||A_b|| delta}`` on ``||D^-1 B d||``,
        the product ``Gamma B d`` and the difference ``d`` (``gamma_{m+2} + u``), and the sum
        (``u ||D^-1 x||``, ``x`` after it). The error map does not change: the plant receives the
        same input, so ``B u`` cancels in the error."""
        dn = math.sqrt(float(d @ d)) + underflow_slack(d.size)
        delta = abs(dt - e.dt) + _U * dt
        quant = delta * (e.nPhi + e.eps) * math.exp(min(self.nA * delta, 700.0)) if delta > 0.0 else 0.0
        rho = ((e.epsG + quant) * self.fB + (self.g_m + _U) * e.fGB) * dn + _U * self.xn(x) + self._uf
        return rho * (1.0 + 8.0 * _U)

    def rho_correct(self, fK: float, fH: float, x_minus: np.ndarray, y: np.ndarray, nu: np.ndarray,
                    x_plus: np.ndarray | None, xm: float | None = None, xp: float | None = None) -> float:
        """Residual bound (balanced) of a Kalman correction ``x^+ = x^- + K (y - H x^-)`` in floating
        point (products ``H x^-`` and ``K nu``, the two sums, and the data's own rounding ``u
        ||y||``); ``fK = ||D^-1 K||_F``, ``fH = ||H D||_F``; ``xm`` and ``xp`` are ``||D^-1 x^-||``
        and ``||D^-1 x^+||`` if the caller has them (then ``x_plus`` is not read)."""
        yn = math.sqrt(float(y.dot(y))) + underflow_slack(y.size)
        nun = math.sqrt(float(nu.dot(nu))) + underflow_slack(nu.size)
        return self.rho_correct_norms(fK, fH, self.xn(x_minus) if xm is None else xm, yn, nun,
                                      self.xn(x_plus) if xp is None else xp, y.size)

    def rho_correct_norms(self, fK: float, fH: float, xm: float, yn: float, nun: float, xp: float, p: int) -> float:
        """:meth:`rho_correct` from the norms ``||D^-1 x^-||``, ``||y||``, ``||nu||`` and ``||D^-1 x^+||``
        (or upper bounds of them) of a sample of ``p`` rows."""
        uf = (self.n + 2) * math.sqrt(p) * UNDERFLOW       # H x^- and y's own underflow
        return (fK * (self.g_n * fH * xm + 2.0 * _U * yn + uf) + self.g_p * fK * nun
                + _U * xp + self._uf) * (1.0 + 8.0 * _U)

    def prior_beta(self, e: Any, dt: float, x0: np.ndarray, xm: np.ndarray, u: np.ndarray | None) -> float:
        """``>= ||D^-1 e^-||`` after the open-loop step ``e`` over ``dt`` from the sets now, for
        both sets: ``||Phi~||_D beta + rho`` (:meth:`beta`; the step's residual, :meth:`rho_step`)."""
        rho = max(self.rho_step(e, dt, x0, xm, ell, None, u) for ell in (self.ell, self.ellv) if ell is not None)
        return (e.nPhi * self.beta() + rho) * (1.0 + 4.0 * _U)

    # ------------------------------------------------------------------ steps
    def _check(self) -> None:
        """Withdraw the bound (module docstring) once a set is no longer finite."""
        if not self.withdrawn and not (self.ell.finite() and (self.ellv is None or self.ellv.finite())):
            self.withdrawn = ("the rounding bound's ellipsoid overflowed (it is no longer finite); "
                              "the bounds are withdrawn until the next reset")

    def _noise(self, ell: ErrorEllipsoid, e: Any, rho: float, GL: np.ndarray | None, keep: bool,
               dt: float = 0.0, vn: float | None = None) -> tuple | None:
        """A step of an ellipsoid through the ZOH cache entry ``e`` over ``dt`` with a held
        innovation: its noise (``vn``, default the held ``sqrt(p) v_max``; 0 for the exact set) and
        its stamp error ``w`` enter through ``Gamma L`` (``||v + w|| <= vn + w``; open-loop steps and
        Kalman prediction steps add none), a declared disturbance as :meth:`disturbed` says (``dt`` 0
        for the exact set: none). The map ``e.E`` is taken in compressed rows where it is sparse
        (:func:`~switchobs_core.bounds.kalman_map.sparse_map`, :func:`open_loop_product`), else
        densely. ``keep``: the step is kept in ``ell`` (None returned), else ``(S, trace S)`` or, through a
        sparse map, a :class:`~switchobs_core.numerics.rounding.PendingSet`."""
        vn = self.vn if vn is None else vn
        c = vn ** 2 if not self.w else (vn + self.w) ** 2 * (1.0 + 4.0 * _U)
        G, c = (GL, c) if GL is not None and c > 0.0 else (None, 0.0)
        G, c, r = self.disturbed(dt, G, c)
        rho += r
        sp = sparse_map(e)
        if sp is not None:      # open_loop_product's set, planned by the kernel where it runs
            remake = (lambda S=ell.S: sp.sandwich_either(S))
            Z = sp.sandwich_either(ell.S, ell.scratch())
            out = None if G is not None else ell.pending_open(Z, sp.abs_rows, sp.c, rho, sp.inf_norm, remake)
            if out is None:
                out = ell.pending(Z, ell.image_bound(sp.abs_matvec), sp.c, rho, sp.inf_norm, G, c, remake)
            if not keep:        # assembled for a reader of the whole set only (PendingSet)
                if e.E is e.Phi:    # a prior's open-loop product: a Kalman sample's step takes it
                    ell.keep_product(sp, out)       # (KalmanMap.sandwich) unless the set was assembled
                return out
            out = (out.full(), out.tr)
        else:
            absE = e.abs_E() if hasattr(e, "abs_E") else None
            out = (ell.propagate_shaped(e.E, rho, G, c, absM=absE) if G is not None
                   else ell.propagate(e.E, rho, absE))
        if keep:
            ell.S, ell.tr = out
            return None
        return out

    def step(self, e: Any, dt: float, x0: np.ndarray, x1: np.ndarray, nu: np.ndarray | None,
             u: np.ndarray | None, extra: float = 0.0) -> None:
        """Both ellipsoids through one propagation step ``e`` (a ZOH cache entry) over ``dt``;
        ``extra``: the residual (balanced) of what the step added besides (:meth:`rho_input`)."""
        if self.withdrawn:
            return
        hit = self._memo is not None and self._same(self._memo[0], e, dt, x0, x1, nu, u, extra)
        if hit:     # the sets propagated() gave for these very arguments: the same doubles (copied)
            out, outv = self._memo[1]
            self._ell.S, self._ell.tr = _whole(out)
            if outv is not None:
                self._ellv.S, self._ellv.tr = _whole(outv)
        self._memo = None
        if hit:
            self._check()
            return
        with np.errstate(over="ignore", invalid="ignore"):
            self._noise(self.ell, e, self.rho_step(e, dt, x0, x1, self.ell, nu, u) + extra,
                        e.GL if nu is not None and self.w else None, True, 0.0, 0.0)
            if self.ellv is not None:
                self._noise(self.ellv, e, self.rho_step(e, dt, x0, x1, self.ellv, nu, u) + extra,
                            e.GL if nu is not None else None, True, dt)
        self._check()

    def _key(self, e: Any, dt: float, x0: np.ndarray, x1: np.ndarray, nu: np.ndarray | None,
             u: np.ndarray | None, extra: float) -> tuple:
        """Everything a step's sets are computed from: the entry, ``dt``, the residual's data, the held
        sample's noise, stamp error and rounding, and the ellipsoids' shape matrices (by identity: a
        step replaces them, never changes them in place); the vectors copied, compared by value."""
        cp = (lambda v: None if v is None else np.array(v, dtype=float, copy=True))
        ell, ellv = self.ell, self.ellv
        return (e, dt, extra, self.vn, self.w, self.nu_err, ell.S, ell.tr, None if ellv is None else ellv.S,
                cp(x0), cp(x1), cp(nu), cp(u))

    def _same(self, key: tuple, e: Any, dt: float, x0: np.ndarray, x1: np.ndarray, nu: np.ndarray | None,
              u: np.ndarray | None, extra: float) -> bool:
        """Whether a step with these arguments computes the sets of ``key`` (:meth:`_key`)."""
        ell, ellv = self.ell, self.ellv
        if not (key[0] is e and key[1] == dt and key[2] == extra and key[3] == self.vn and key[4] == self.w
                and key[5] == self.nu_err and key[6] is ell.S and key[7] == ell.tr
                and key[8] is (None if ellv is None else ellv.S)):
            return False
        return all((a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))
                   for a, b in zip(key[9:], (x0, x1, nu, u)))

    def propagated(self, e: Any, dt: float, x0: np.ndarray, xp: np.ndarray, nu: np.ndarray | None,
                   u: np.ndarray | None, extra: float = 0.0, *, lazy: bool = False) -> tuple[Any, Any]:
        """The shape matrices after the step ``e`` over ``dt``: ``(S, S_noise or None)``, read-only (``extra``
        as in :meth:`step`; a sparse map in compressed rows, as :meth:`step` takes it). The sets stay
        as they are; a :meth:`step` with the same arguments next takes copies of these. ``lazy``: a
        set through a sparse map is a :class:`~switchobs_core.numerics.rounding.PendingSet` (assembled
        at its first whole read; its blocks and trace without the n x n passes)."""
        key = self._key(e, dt, x0, xp, nu, u, extra) if not self.withdrawn else None
        with np.errstate(over="ignore", invalid="ignore"):
            out = self._noise(self.ell, e, self.rho_step(e, dt, x0, xp, self.ell, nu, u) + extra,
                              e.GL if nu is not None and self.w else None, False, 0.0, 0.0)
            outv = None
            if self.ellv is not None:
                outv = self._noise(self.ellv, e, self.rho_step(e, dt, x0, xp, self.ellv, nu, u) + extra,
                                   e.GL if nu is not None else None, False, dt)
        # kept for a step with the same arguments (the sample at that time: prior, then update)
        self._memo = None if key is None else (key, (out, outv))
        pick = (lambda o: (o if lazy else o.full()) if isinstance(o, PendingSet) else o[0])
        return pick(out), None if outv is None else pick(outv)

    def correct(self, M: np.ndarray, rho: float, K: np.ndarray, H: np.ndarray, p: int, channel: int) -> None:
        """Both ellipsoids through a Kalman correction ``e^+ = M e^- + r + K v`` with the computed
        ``M = fl(I - fl(K H))``: it differs from ``I - K H`` by ``gamma_{p+1} (I + |K| |H|)``
        entrywise, ``gamma_{p+1} kappa`` in the balanced 2-norm, times ``||e^-||``."""
        if self.withdrawn:
            return
        emap = gamma(H.shape[0] + 1) * self.gain_norms(K, H)[2]
        with np.errstate(over="ignore", invalid="ignore"):
            if self.w:      # e^+ = (I - K H) e^- + K w: the stamp error
                self.ell.step_shaped(M, rho + emap * math.sqrt(self.ell.lam_scaled()), K, self._wc(0, 0.0))
            else:
                self.ell.step(M, rho + emap * math.sqrt(self.ell.lam_scaled()))
            if self.ellv is not None:      # e^+ = (I - K H) e^- + K (v + w)
                self.ellv.step_shaped(M, rho + emap * math.sqrt(self.ellv.lam_scaled()), K,
                                      self._wc(p, self.noise_max[channel - 1]))
        self._check()

    def fused(self, e: Any, dt: float, m: Any, x0: np.ndarray, xm: np.ndarray, rc: float,
              K: np.ndarray, p: int, channel: int, u: np.ndarray | None = None,
              norms: tuple[float, float] | None = None) -> None:
        """Both ellipsoids through a Kalman sample's fused map ``M = (I - K H) e^{A dt}``
        (a :class:`~switchobs_core.bounds.kalman_map.KalmanMap`: ``M S M'`` dense or factored, with its
        rounding's ``(w, c)``): the prediction's residual (input ``u`` held, None: zero) through
        ``||I - K H||_2`` plus the correction's ``rc`` and the dense map's own rounding; ``norms``:
        ``(||D^-1 x0||, ||D^-1 xm||)`` if the caller has them."""
        if self.withdrawn:
            return
        xs, xs1 = (self.xn(x0), self.xn(xm)) if norms is None else norms
        with np.errstate(over="ignore", invalid="ignore"):
            for ell, noisy in ((self.ell, False), (self.ellv, True)):
                if ell is None:
                    continue
                en = math.sqrt(ell.lam_scaled())
                rho = m.nIKH * self._rho_step(e, dt, xs, xs1, en, None, u) + rc + m.emap * en
                if not noisy and not self.w and m.step(ell, rho):     # the compiled factored step, where it runs
                    continue
                Z, w, c, mn = m.sandwich(ell)
                if noisy:       # e^+ = (I - K H) (e^- + d) + K (v + w)
                    G, cg, r = self.disturbed(dt, K, self._wc(p, self.noise_max[channel - 1]), K, m.H, m.nIKH)
                    ell.S, ell.tr = ell.propagate_shaped_product(Z, w, c, rho + r, mn, G, cg)
                elif self.w:    # e^+ = (I - K H) e^- + K w: the stamp error
                    ell.S, ell.tr = ell.propagate_shaped_product(Z, w, c, rho, mn, K, self._wc(0, 0.0))
                else:
                    ell.S, ell.tr = ell.propagate_product(Z, w, c, rho, mn)
        self._check()

    def fused_sample(self, f: Any, channel: int) -> bool:
        """:meth:`fused` for a Kalman sample's :class:`~switchobs_core.runtime.error_maps.FusedMap` ``f``
        through a dense map with no shaped term (no clock tolerance, so no stamp error; the noise set's
        noise and disturbance none on this ``channel``): each set by
        :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.step_dense`, the residual of
        :meth:`fused` (:meth:`_rho_step` through ``||I - K H||``, :meth:`rho_correct_norms`, the map's
        own rounding) as one linear form in the step's norms with coefficients kept per map and step
        (:meth:`_fused_form`). False (nothing done) where that does not apply: the caller takes
        :meth:`fused`."""
        m = f.m
        ellv = self._ellv
        if self.tolerance or self.phase is not None or self.withdrawn or (
                ellv is not None and (self.reach is not None or self.noise_max[channel - 1])):
            return False
        dt = f.dt
        hit = m.rho_form
        if hit is None or hit[0] is not self or hit[1] != dt:
            dense = m.dense_abs(self.d)
            if dense is None:
                return False
            hit = m.rho_form = (self, dt, self._fused_form(m, dt, f.y.size), dense)
        a_xs, a_xs1, a_xsp, a_yn, a_nun, a_0, a_en = hit[2]
        xs, xs1, xsp = self.fused_norms(f.x0, f.x_minus, f.x_plus)
        y, nu = f.y, f.nu
        base = a_xs * xs + a_xs1 * xs1 + a_xsp * xsp + a_yn * _norm(y) + a_nun * _norm(nu) + a_0
        self.w = 0.0
        E, dense = m.E, hit[3]
        for ell in (self._ell, ellv):
            if ell is not None:
                ell.step_dense(E, dense, (base + a_en * math.sqrt(ell.lam_scaled())) * (1.0 + 32.0 * _U))
                if not math.isfinite(ell.tr):
                    self._check()
        return True

    def _fused_form(self, m: Any, dt: float, p: int) -> tuple[float, ...]:
        """The coefficients of ``rho = a_xs ||x0|| + a_xs1 ||x^-|| + a_xsp ||x^+|| + a_yn ||y|| + a_nun ||nu||
        + a_0 + a_en ||e||`` (balanced norms) that :meth:`fused` computes term by term for the map ``m`` over
        ``dt`` with ``p`` rows: :meth:`_rho_step` (no input) times ``||I - K H||``, plus
        :meth:`rho_correct_norms`, plus the map's own rounding ``emap ||e||``. Each is a sum of products
        of the same constants; :meth:`fused_sample` rounds the form up by ``(1 + 32 u)`` for the
        regrouping."""
        e = m.e
        delta = abs(dt - e.dt) + _U * dt
        q = (e.nPhi + e.eps) * math.expm1(self.nA * delta) * (1.0 + 4.0 * _U) if delta > 0.0 else 0.0
        k8 = 1.0 + 8.0 * _U
        nk = m.nIKH * k8
        fK, fH = m.fK, m.fH
        return (nk * ((e.eps + q) + self.g_n * e.fPhi),
                nk * 2.0 * _U + k8 * fK * self.g_n * fH,
                k8 * _U,
                k8 * fK * 2.0 * _U,
                k8 * self.g_p * fK,
                nk * self._uf + k8 * (fK * (self.n + 2) * math.sqrt(p) * UNDERFLOW + self._uf),
                nk * ((e.eps + q) + e.emap) + m.emap)

    def _wc(self, p: int, v_max: float) -> float:
        """``(sqrt(p) v_max + w)^2`` rounded up: the squared norm bound of a sample's noise
        (``p`` rows within ``v_max``) plus its stamp error (``p v_max^2`` without one)."""
        if not self.w:
            return p * v_max ** 2
        return (math.sqrt(p) * v_max * (1.0 + 2.0 * _U) + self.w) ** 2 * (1.0 + 4.0 * _U)

    # ------------------------------------------------------------------ bounds
    def bounds(self, S: np.ndarray | None = None, Sv: np.ndarray | None = None, *,
               amortised: bool = False) -> tuple[float, float | None]:
        """``(exact, noise)``: upper bounds of ``sqrt(lambda_max)`` of the shape matrices (default
        the current ones): the eigenvalue problem's, or with ``amortised`` (current sets only)
        :mod:`switchobs_core.bounds.read`'s (a verified upper bound per anchor, O(n^2) in between,
        within the factor that module states); ``inf`` for a withdrawn bound (never raises)."""
        noisy0 = None if self._ellv is None else math.inf
        if self.withdrawn:
            return math.inf, noisy0
        if self.phase is not None and self.phase.j >= 0 and S is None and Sv is None:
            return self.phase.bounds()      # finite while it holds (PhaseBound.sample withdraws otherwise)
        ev = self._ellv
        if not amortised and S is None and Sv is None and self._ell.tr < 1e140 and (ev is None or ev.tr < 1e140):
            exact = self._ell.bound()       # |S_ij| <= trace S: nothing overflows (no error state)
            noisy = None if ev is None else ev.bound()
            if math.isfinite(exact) and (noisy is None or math.isfinite(noisy)):
                return exact, noisy
        if amortised and S is None and Sv is None:     # the read sets up its own error state where numpy runs
            exact, noisy = self._read.read(self._ell), None if ev is None else self._readv.read(ev)
        else:
            with np.errstate(over="ignore", invalid="ignore"):
                exact = self.ell.bound(S)
                noisy = None if self.ellv is None else self.ellv.bound(Sv)
        if not math.isfinite(exact) or (noisy is not None and not math.isfinite(noisy)):
            if S is None and Sv is None:
                self.withdrawn = self.withdrawn or ("the rounding bound is no longer finite; the bounds are "
                                                    "withdrawn until the next reset")
            return math.inf, noisy0
        return exact, noisy
