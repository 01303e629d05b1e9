"""Online Kalman filter for switched outputs (the ``kalman-online`` family; beyond the paper).

For schedules with no promise (random residence times, assumption A2) the covariance is
propagated at run time. The formulas are those of :mod:`switchobs_core.design.riccati` (the same functions as the
offline design), with ``(Phi, Gamma B, Q_d)`` cached per step ``dt`` rounded to 1 ns.
Cost: O(n^3) per sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..design.riccati import DiscretizationCache
from ..exceptions import InvalidArgument
from ..model.noise import NoiseModel, default_noise
from ..numerics.kalman_step import correct_state, gain, joseph, predict_cov
from ..numerics.propagation import DEFAULT_DT_RESOLUTION

__all__ = ["OnlineKalman"]


class OnlineKalman:
    """Discrete Kalman filter at the sample stamps of a switched-output system.

    ``f = OnlineKalman(system, noise, x0=None)``; ``x = f.update(t, channel, y, rows=None, u=None)``

    Parameters
    ----------
    system : LTISystem
    noise : NoiseModel, optional
        Default :func:`~switchobs_core.model.noise.default_noise`. ``noise.P0`` is the covariance
        of ``x0``.
    x0 : (n,) array_like, optional
        Estimate before the first sample (zeros).
    dt_resolution : float or None
        Rounding of the step for the discretisation cache (default 1 ns).

    Attributes
    ----------
    x, P : the posterior after the last sample; ``P_prior``, ``K``: its prior and gain.
    """

    def __init__(self, system: Any, noise: NoiseModel | None = None, *, x0: Any = None,
                 dt_resolution: float | None = DEFAULT_DT_RESOLUTION, cache_size: int = 64) -> None:
        self.system = system
        self.noise = default_noise(system) if noise is None else noise
        if not isinstance(self.noise, NoiseModel):
            raise InvalidArgument(f"noise must be a NoiseModel; got {type(noise).__name__}")
        self.noise.check_system(system)
        n = system.n
        self.x = np.zeros(n) if x0 is None else np.array(x0, dtype=float).reshape(n)
        self.P = np.array(self.noise.P0)
        self.P_prior: np.ndarray | None = None
        self.K: np.ndarray | None = None
        self.t: float | None = None
        self.cache = DiscretizationCache(np.asarray(system.A, float), np.asarray(system.B, float), self.noise.Q_c,
                                         maxsize=cache_size, dt_resolution=dt_resolution)

    def update(self, t: float, channel: int, y: Any, rows: Sequence[int] | None = None, u: Any = None) -> np.ndarray:
        """Predict to ``t`` (``u`` held since the last sample), then correct with rows ``rows`` of ``channel``."""
        if self.t is not None:
            if not t >= self.t:
                raise InvalidArgument(f"sample time {t!r} is before the previous sample {self.t!r}")
            Phi, GB, Qd = self.cache.get(t - self.t)
            # x^- = Phi x^+ + Gamma B u ; P^- = Phi P^+ Phi' + Q_d
            self.x = Phi @ self.x if u is None else Phi @ self.x + GB @ np.asarray(u, float)
            self.P = predict_cov(self.P, Phi, Qd)
        self.t = float(t)
        C = self.system.C[channel - 1]
        H = C if rows is None else C[list(rows)]
        R = self.noise.R(channel, rows)
        self.P_prior = self.P
        self.K = gain(self.P, H, R)
        self.x = correct_state(self.x, self.K, H, np.asarray(y, dtype=float))
        self.P = joseph(self.P, self.K, H, R)
        return self.x
