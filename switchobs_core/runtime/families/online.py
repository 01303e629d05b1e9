"""The online Kalman family: the Riccati recursion at run time, any schedule (beyond the paper).

At a sample with rows ``H = C_rho[rows]`` (e:outputs) the estimate and the covariance are
propagated exactly (``P^- = e^{A dt} P^+ e^{A dt}' + Q_d``, :mod:`switchobs_core.runtime.covariance`;
by the observer's step, or fused with the correction when no input is held) and the family
corrects (Joseph form, :func:`~switchobs_core.design.riccati.joseph`):

.. math::

    K = P^- H' (H P^- H' + R)^{-1}, \\quad x^+ = x^- + K (y - H x^-), \\quad
    P^+ = (I - K H) P^- (I - K H)' + K R K'

The correction :func:`kalman_correct` is the one place the Kalman step is written: the table
family (:mod:`switchobs_core.runtime.families.kalman`) uses it with stored gains.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ...bounds.kalman_map import KalmanMap
from ...model.noise import NoiseModel, default_noise
from ...numerics.kalman_step import gain, joseph
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
    It keeps the posterior covariance ``P`` of the last sample.
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
        self._R: dict = {}
        self._I = np.eye(self._ctx.n)
        self._P: np.ndarray = noise.P0.copy()
        noise.check_system(self._ctx.system)
        self._cov = CovarianceStep(self._ctx.A, self._ctx.B, noise, self._ctx.dt_resolution)

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
        self._P = self.noise.P0.copy()

    def fuses(self, input_held: bool) -> bool:
        """The prediction is fused with the correction when no input was held over the step."""
        return not input_held

    def stepped(self, e: Any, dt: float) -> None:
        self._P = self._cov.step(self._P, e, dt)

    def covariance(self) -> np.ndarray | None:
        return self._P.copy()

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
            self._P = self._cov.step(self._P, e, dt)
        return xm, (e, dt, x)

    def correct_online(self, channel: int, rows: tuple | None, H: np.ndarray, y: np.ndarray, x: np.ndarray,
                       prediction: tuple | None = None) -> Correction:
        """The Riccati step on the prior ``P`` and the correction of ``x = x^-`` with its gain."""
        R = self._R.get((channel, rows))
        if R is None:
            R = self._R[(channel, rows)] = self.noise.R(channel, rows)
        K = gain(self._P, H, R)
        self._P = joseph(self._P, K, H, R)
        xp, m = kalman_correct(x, K, H, y, self._I, prediction)
        return Correction(xp, (m,))

    def sample(self, s: Sample) -> Correction:
        x, prediction = s.x, None
        if s.dt > 0:
            x, prediction = self.predict(x, s.dt)
        return self.correct_online(s.channel, s.rows, self._ctx.rows_of(s.channel, s.rows), s.y, x, prediction)
