"""The online Kalman family: the Riccati recursion at run time, any schedule, in square-root form (beyond the paper).

At a sample with rows ``H = C_rho[rows]`` (e:outputs) the estimate and the covariance are
propagated exactly (``P^- = e^{A dt} P^+ e^{A dt}' + Q_d``; by the observer's step, or fused with
the correction when no input is held) and the family corrects:

.. math::

    K = P^- H' (H P^- H' + R)^{-1}, \\quad x^+ = x^- + K (y - H x^-), \\quad
    P^+ = (I - K H) P^- (I - K H)' + K R K'

Square-root form. The covariance is kept as a factor ``L``, ``P = L L'``. The correction is one
QR of the pre-array (:func:`~switchobs_core.numerics.kalman_step.sqrt_correct`), which gives
``K`` and a triangular ``L^+`` with ``L^+ L^{+'}`` the Joseph form's ``P^+`` in exact arithmetic:
positive semidefinite by construction, with no cancellation however much a view reduces the
covariance. The prediction (:meth:`~switchobs_core.runtime.covariance.CovarianceStep.factor_step`)
is the Cholesky factor of ``e^{A dt} L L' e^{A dt}' + Q_d`` while that is well conditioned (within
about 1e12: four digits or more in its smallest direction, as a design accepts; the cheap path),
else the exact square root ``[e^{A dt} L, Q_d^{1/2}]``, which the correction's QR compresses: the
factor then carries the square root of the covariance's dynamic range, and a covariance spanning
1e20, past the 16 digits where the covariance form's ``S = H P H' + R`` loses positive
definiteness, is a factor spanning 1e10. So ``P`` stays symmetric positive definite over any run
length and stamp pattern as long as the arithmetic allows. The covariance itself
(:meth:`OnlineKalmanGains.covariance`, and what the table family reads after a departure) is
``L L'``, formed on demand. Against the Joseph form on the same samples the estimates differ in
the last bits (an equivalent formula, rounded differently): at most 4.6e-14 of the estimate and
3.6e-12 of the covariance on the paper's model, 3.8e-13 and 1.2e-12 on a stiff system
(bench/RESULTS.md).

Loss of positive definiteness. If even the factor runs out of digits (singular to working
precision, or an overflow: :func:`~switchobs_core.numerics.kalman_step.check_factor`), the family
restarts its recursion from the noise model's ``P0`` as the prior of this sample and corrects with
that gain; the :class:`~switchobs_core.runtime.families.base.Correction` it returns says why in
``lost`` (the :class:`~switchobs_core.exceptions.CovarianceError` raised inside the step, one line).
The observer answers with it and withdraws what rests on the covariance (its ``P`` and the
chi-square gate) until its reset, with that reason; the rigorous bound goes on, since the error
map of the gain applied is exact whatever covariance it came from.

The correction :func:`kalman_correct` is the one place the Kalman step of the estimate is
written: the table family (:mod:`switchobs_core.runtime.families.kalman`) uses it with stored gains.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ...bounds.kalman_map import KalmanMap
from ...exceptions import CovarianceError
from ...model.noise import NoiseModel, default_noise
from ...numerics.kalman_step import check_factor, compress_factor, psd_sqrt, sqrt_correct, symmetrize
from ..covariance import CovarianceStep
from ..error_maps import CorrectionMap, FusedMap
from .base import OPEN_LOOP, Correction, FamilyContext, Sample, ScheduledCycle, check_bounds, check_cycles
from .lmi import LmiGains

__all__ = ["OnlineKalmanGains", "kalman_correct"]


def kalman_correct(x: np.ndarray, K: np.ndarray, H: np.ndarray, y: np.ndarray, identity: np.ndarray,
                   prediction: tuple | None = None) -> tuple[np.ndarray, Any]:
    """``x^+ = x^- + K (y - H x^-)`` for ``x = x^-`` and the error map of what was applied:
    ``(x^+, map)``. The innovation first keeps the rounding of the estimate at the level of the
    error, not of ``||x||``.

    ``prediction``: the step just taken by :meth:`OnlineKalmanGains.predict`, ``(e, dt, x0)``
    (``x^- = e^{A dt} x0``); the sample's error map is then the fused ``(I - K H) e^{A dt}``
    (a :class:`~switchobs_core.runtime.error_maps.FusedMap` of a
    :class:`~switchobs_core.bounds.kalman_map.KalmanMap`, one step of the bound); without it the
    map is ``I - K H`` alone (:class:`~switchobs_core.runtime.error_maps.CorrectionMap`: the
    prediction was applied as its own step). ``identity`` is the n x n ``I``."""
    nu = y - H @ x
    xp = x + K @ nu
    if prediction is None:
        return xp, CorrectionMap(K, H, identity, y, nu, x, xp)
    e, dt, x0 = prediction
    # E_k = (I - K H) e^{A dt}: dense, or in factors when e^{A dt} is sparse (kalman_map)
    return xp, FusedMap(KalmanMap(e, K, H, identity), dt, x0, x, xp, y, nu)


class OnlineKalmanGains:
    """The ``kalman-online`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``OnlineKalmanGains(ctx, table, mode, cycles, bounds=None, noise=None)``: the noise model is
    ``noise``, else the one of a Kalman table, else :func:`~switchobs_core.model.noise.default_noise`.
    It keeps the posterior covariance of the last sample as its factor (module docstring).
    """

    name: ClassVar[str] = "kalman-online"
    paper_envelope: ClassVar[bool] = False
    holds: ClassVar[tuple[str, ...]] = ("innovation",)
    kalman = None
    #: Nothing is held between samples: the observer's steps are open loop.
    held = None

    def __init__(self, ctx: FamilyContext, table: Any, mode: str, cycles: Any, *, bounds: Any = None,
                 noise: Any = None, **_: Any) -> None:
        self._ctx = ctx
        cycles = self._schedule(mode, cycles, bounds)
        if noise is None:
            stored = getattr(table, "family", "lmi") == "kalman"
            noise = NoiseModel.from_dict(table.kalman[0]["noise"]) if stored else default_noise(ctx.system)
        self._keep_noise(noise)

    def _keep_noise(self, noise: Any) -> None:
        """The noise model of the covariance, checked against the system, and its propagation."""
        self.noise = noise
        self.track_covariance = True
        self._R: dict = {}          # (channel, rows) -> R^{1/2}
        self._I = np.eye(self._ctx.n)
        noise.check_system(self._ctx.system)
        self._L0 = psd_sqrt(noise.P0)
        self._L = self._L0
        self._Pc: np.ndarray | None = noise.P0.copy()
        self._cov = CovarianceStep(self._ctx.A, self._ctx.B, noise, self._ctx.dt_resolution)

    @property
    def _P(self) -> np.ndarray:
        """The covariance ``L L'`` of the factor kept (formed on the first read after a change)."""
        P = self._Pc
        if P is None:
            L = self._L
            P = self._Pc = symmetrize(L @ L.T)
        return P

    @_P.setter
    def _P(self, P: np.ndarray) -> None:
        """Keep ``P`` (symmetric PSD) from now on, as its factor."""
        self._L = psd_sqrt(P)
        self._Pc = P

    def _predict_factor(self, e: Any, dt: float) -> None:
        """The factor through the open-loop step ``e`` over ``dt`` (compressed first if a step left it wide)."""
        L = self._L
        if L.shape[1] > L.shape[0]:
            L = compress_factor(L)
        self._L = self._cov.factor_step(L, e, dt)
        self._Pc = None

    def _schedule(self, mode: str, cycles: Any, bounds: Any) -> list:
        """The promised cycles (bookkeeping only: the gains do not depend on them)."""
        if mode == "robust":
            self.designs = (ScheduledCycle(None, h_bounds=bounds),)
            self.promised = (None,)
            self.bounds = check_bounds(bounds)
            return []
        cycles = check_cycles(cycles, mode, self._ctx.N)
        self.designs = tuple(ScheduledCycle(c) for c in cycles)
        self.promised = tuple(cycles)
        self.bounds = None
        return cycles

    @classmethod
    def design_table(cls, system: Any, cycles: Any, **kw: Any) -> Any:
        """No stored gains are needed: the paper's table serves the bookkeeping."""
        return LmiGains.design_table(system, cycles, **kw)

    # ------------------------------------------------------------------ protocol
    @property
    def source(self) -> str:
        return "online"

    def reset(self) -> None:
        self._L = self._L0
        self._Pc = self.noise.P0.copy()

    def fuses(self, input_held: bool) -> bool:
        """The prediction is fused with the correction when no input was held over the step."""
        return not input_held

    def stepped(self, e: Any, dt: float) -> None:
        self._predict_factor(e, dt)

    def covariance(self) -> np.ndarray | None:
        return self._P.copy()

    @property
    def factor(self) -> np.ndarray:
        """The factor ``L`` of the recursion's covariance, ``P = L L'`` (a copy; n x n, or n x 2n
        between a prediction and its correction): what carries the covariance when ``P`` itself
        spans more than a double resolves (module docstring)."""
        return self._L.copy()

    def stored_prior(self, t: float, dt: float, cols: np.ndarray | None = None) -> np.ndarray | None:
        """With ``cols`` (a consistency test's block) and ``dt > 0``: the prior's block on ``cols``
        from the recursion's factor (:meth:`~switchobs_core.runtime.covariance.CovarianceStep.prior_block`;
        nothing is held: the open-loop step), without forming the n x n ``P`` and its prior; else
        None (the observer propagates :meth:`covariance`)."""
        if cols is None or not dt > 0:
            return None
        e = self._ctx.zoh(OPEN_LOOP, dt)
        Pc = self._Pc
        return self._cov.prior_block(self._L if Pc is None else Pc, e, dt, np.asarray(cols), factor=Pc is None)

    def predict_covariance(self, P: np.ndarray, e: Any, dt: float) -> np.ndarray:
        return self._cov.prior(P, e, dt)

    def depart(self, why: str) -> None:
        return None

    def set_covariance(self, P: np.ndarray) -> None:
        self._P = P

    # ------------------------------------------------------------------ samples
    def predict(self, x: np.ndarray, dt: float, *, covariance: bool = True) -> tuple:
        """``x^- = e^{A dt} x^+`` (no input held: :meth:`fuses`) and ``P^- = e^{A dt} P^+ e^{A dt}' + Q_d``
        (unless ``covariance`` is False); returns ``(x^-, prediction)`` with the ``prediction`` of
        :func:`kalman_correct`."""
        e = self._ctx.zoh(OPEN_LOOP, dt)
        xm = e.Phi @ x
        if covariance:
            self._predict_factor(e, dt)
        return xm, (e, dt, x)

    def correct_online(self, channel: int, rows: tuple | None, H: np.ndarray, y: np.ndarray, x: np.ndarray,
                       prediction: tuple | None = None) -> Correction:
        """The square-root Riccati step on the prior's factor and the correction of ``x = x^-`` with
        its gain; a factor out of digits restarts the recursion from ``P0`` and corrects with that
        gain, the :class:`Correction` saying why in ``lost`` (module docstring)."""
        Rs = self._R.get((channel, rows))
        if Rs is None:
            Rs = self._R[(channel, rows)] = psd_sqrt(self.noise.R(channel, rows))
        try:
            K, L = _corrected(self._L, H, Rs, f"the online Kalman recursion at a sample of channel {channel}")
        except CovarianceError as err:
            K, L, _ = sqrt_correct(self._L0, H, Rs)
            self._L, self._Pc = L, None
            xp, m = kalman_correct(x, K, H, y, self._I, prediction)
            return Correction(xp, (m,), lost=f"{err}; the recursion restarts from P0 (the covariance and what "
                                             "rests on it no longer hold)")
        self._L, self._Pc = L, None
        xp, m = kalman_correct(x, K, H, y, self._I, prediction)
        return Correction(xp, (m,))

    def sample(self, s: Sample) -> Correction:
        x, prediction = s.x, None
        if s.dt > 0:
            x, prediction = self.predict(x, s.dt)
        return self.correct_online(s.channel, s.rows, self._ctx.rows_of(s.channel, s.rows), s.y, x, prediction)


def _corrected(L: np.ndarray, H: np.ndarray, Rs: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """``(K, L^+)`` of :func:`~switchobs_core.numerics.kalman_step.sqrt_correct`, checked: finite,
    and after an ill-conditioned prior (a wide factor) nonsingular to working precision
    (:func:`~switchobs_core.numerics.kalman_step.check_factor`; a well-conditioned prior's
    ``L^+`` is, and the next prediction's Cholesky tests it again)."""
    try:
        with np.errstate(all="ignore"):
            K, Lp, _ = sqrt_correct(L, H, Rs)
    except np.linalg.LinAlgError as err:
        raise CovarianceError(f"{what}: the innovation covariance's factor is singular ({err})") from None
    if L.shape[1] > L.shape[0]:     # the exact square root of an ill-conditioned prior: are digits left?
        check_factor(Lp, what)
    elif not np.all(np.isfinite(Lp)):
        raise CovarianceError(f"{what}: the covariance factor overflowed (an entry is not finite)")
    if not np.all(np.isfinite(K)):
        raise CovarianceError(f"{what}: the gain is not finite")
    return K, Lp
