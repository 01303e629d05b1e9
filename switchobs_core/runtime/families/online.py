"""The online Kalman family: the Riccati recursion at run time, any schedule (beyond the paper).

At a sample with rows ``H = C_rho[rows]`` (e:outputs) the observer has propagated the estimate
and the covariance exactly (``P^- = e^{A dt} P^+ e^{A dt}' + Q_d``, :mod:`switchobs_core.design.riccati`); the
family corrects (Joseph form, :func:`~switchobs_core.design.riccati.joseph`):

.. math::

    K = P^- H' (H P^- H' + R)^{-1}, \\quad x^+ = x^- + K (y - H x^-), \\quad
    P^+ = (I - K H) P^- (I - K H)' + K R K'

The correction :func:`kalman_correct` is the one place the observer's Kalman step is written:
the table family (:mod:`switchobs_core.runtime.families.kalman`) uses it with stored gains.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ...bounds.kalman_map import KalmanMap
from ...model.noise import NoiseModel, default_noise
from ...numerics.kalman_step import gain, joseph
from .base import ScheduledCycle, check_bounds, check_cycles
from .lmi import LmiGains

__all__ = ["OnlineKalmanGains", "kalman_correct"]


def kalman_correct(obs: Any, K: np.ndarray, H: np.ndarray, y: np.ndarray, step: tuple | None = None) -> None:
    """``x^+ = x^- + K (y - H x^-)`` on ``obs``'s estimate and its error map (applied to ``Phi`` and
    the rigorous bound). The innovation first keeps the rounding of the estimate at the level of
    the error, not of ``||x||``.

    ``step``: the prediction just taken by :meth:`OnlineKalmanGains.predict` (``e``, ``dt``,
    ``||x^+||`` before it, ``||x^-||``); the sample's error map is then the fused
    ``(I - K H) e^{A dt}`` (a :class:`~switchobs_core.bounds.kalman_map.KalmanMap`, one step of the
    bound); without it the map is
    ``I - K H`` alone (the prediction was applied as its own step)."""
    x = obs._x
    xn = math.sqrt(float(x @ x))
    nu = y - H @ x
    x += K @ nu
    b = obs._bound
    if step is None:
        obs.apply_correction(K, H)
        if b is not None:
            M = obs._I - K @ H
            rho = b.rho_correct(float(np.linalg.norm(K)), float(np.linalg.norm(H)), xn, math.sqrt(float(y @ y)),
                                math.sqrt(float(nu @ nu)), math.sqrt(float(x @ x)))
            b.correct(M, rho, K, y.size, obs._channel)
        return
    e, dt, x0n, xmn = step
    # E_k = (I - K H) e^{A dt}: dense, or in factors when e^{A dt} is sparse (kalman_map)
    M = KalmanMap(e, K, H, obs._I)
    obs.apply_map(M)
    if b is not None:
        rc = b.rho_correct(M.fK, M.fH, xmn, math.sqrt(float(y @ y)), math.sqrt(float(nu @ nu)),
                           math.sqrt(float(x @ x)))
        b.fused(e, dt, M, x0n, xmn, rc, K, y.size, obs._channel)


class OnlineKalmanGains:
    """The ``kalman-online`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``OnlineKalmanGains(obs, table, mode, cycles, bounds=None, noise=None)``: the noise model is
    ``noise``, else the one of a Kalman table, else :func:`~switchobs_core.model.noise.default_noise`.
    """

    name: ClassVar[str] = "kalman-online"
    paper_envelope: ClassVar[bool] = False
    holds: ClassVar[tuple[str, ...]] = ("innovation",)
    kalman = None

    def __init__(self, obs: Any, table: Any, mode: str, cycles: Any, *, bounds: Any = None, noise: Any = None,
                 **_: Any) -> None:
        cycles = self._schedule(obs, mode, cycles, bounds)
        if noise is None:
            stored = getattr(table, "family", "lmi") == "kalman"
            noise = NoiseModel.from_dict(table.kalman[0]["noise"]) if stored else default_noise(obs.system)
        self.noise = noise
        self.track_covariance = True
        self._R: dict = {}

    def _schedule(self, obs: Any, mode: str, cycles: Any, bounds: Any) -> list:
        """The promised cycles (bookkeeping only: the gains do not depend on them)."""
        if mode == "robust":
            self.designs = (ScheduledCycle(None, h_bounds=bounds),)
            self.promised = (None,)
            self.bounds = check_bounds(bounds)
            return []
        cycles = check_cycles(cycles, mode, obs.N)
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

    def reset(self, obs: Any) -> None:
        return None

    def fuses(self, obs: Any) -> bool:
        """The prediction is fused with the correction when no input was held over the step."""
        return obs._u_zero

    def steps_covariance(self) -> bool:
        return True

    def covariance(self, obs: Any) -> np.ndarray | None:
        return obs._P.copy()

    def held_noise(self, obs: Any, e: Any) -> None:
        return None

    def depart(self, obs: Any, why: str) -> None:
        return None

    def predict(self, obs: Any, dt: float, *, covariance: bool = True) -> tuple:
        """``x^- = e^{A dt} x^+`` (no input held: :meth:`fuses`) and ``P^- = e^{A dt} P^+ e^{A dt}' + Q_d``
        (unless ``covariance`` is False); returns the ``step`` of :func:`kalman_correct`."""
        e = obs._cache.step(obs._key, dt)
        xn = math.sqrt(float(obs._x @ obs._x))
        x = e.Phi @ obs._x
        obs._x = x
        if covariance:
            obs._propagate_covariance(e, dt)
        return e, dt, xn, math.sqrt(float(x @ x))

    def correct_online(self, obs: Any, channel: int, rows: tuple | None, H: np.ndarray, y: np.ndarray,
                       step: tuple | None = None) -> None:
        """The Riccati step on ``obs._P`` (the prior) and the correction with its gain."""
        R = self._R.get((channel, rows))
        if R is None:
            R = self._R[(channel, rows)] = obs.noise.R(channel, rows)
        K = gain(obs._P, H, R)
        obs._P = joseph(obs._P, K, H, R)
        kalman_correct(obs, K, H, y, step)

    def sample(self, obs: Any, t: float, dt: float, channel: int, y: np.ndarray, rows: tuple | None) -> None:
        step = self.predict(obs, dt) if dt > 0 else None
        self.correct_online(obs, channel, rows, obs.rows_of(channel, rows), y, step)
