"""The paper's gain family: LMI gains per cycle, the innovation (or measurement) held (Section 4).

At a sample on channel ``i`` the gain ``L_i`` of the current design (per cycle, e:L_original)
is selected and the innovation ``nu = y - C_i x_hat`` (``hold="innovation"``) or the sample
(``hold="measurement"``) is held until the next sample; the observer's next exact step applies
it (e:switched_observer). A sample inside a design's dead time gets no gain. With a noise model
the covariance is propagated through the exact error map, with the held noise driven through
``Gamma L`` (:meth:`LmiGains.held_noise`).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ...design.lmi import design_table
from ...exceptions import InvalidArgument
from ...model.noise import default_noise
from .base import check_bounds, check_cycles

__all__ = ["LmiGains"]


class LmiGains:
    """The ``lmi`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``LmiGains(obs, table, mode, cycles, bounds=None, noise=None, track_covariance=None)``
    """

    name: ClassVar[str] = "lmi"
    paper_envelope: ClassVar[bool] = True
    holds: ClassVar[tuple[str, ...]] = ("innovation", "measurement")
    kalman = None

    def __init__(self, obs: Any, table: Any, mode: str, cycles: Any, *, bounds: Any = None, noise: Any = None,
                 track_covariance: bool | None = None, **_: Any) -> None:
        if getattr(table, "family", "lmi") != "lmi":
            raise InvalidArgument(f"family 'lmi' needs an LMI gain table; this table holds {table.family!r} gains")
        # 1. designs of the mode
        if mode == "robust":
            d = getattr(table, "robust", None)
            if d is None:
                raise InvalidArgument("table has no robust design (table.robust is None); "
                                      "design one with design_table(..., robust=(h_min, h_max))")
            self.designs = (d,)
            self.promised = (None,)
            self.bounds = check_bounds(getattr(d, "h_bounds", None) if bounds is None else bounds)
        else:
            cycles = check_cycles(cycles, mode, obs.N)
            self.designs = tuple(table.lookup(c) for c in cycles)
            self.promised = tuple(cycles)
            self.bounds = None
        for d in self.designs:
            for i, Li in enumerate(d.L):
                if np.shape(Li) != (obs.n, obs.p[i]):
                    raise InvalidArgument(f"design gain L_{i + 1} has shape {np.shape(Li)}; "
                                          f"expected {(obs.n, obs.p[i])}")
        self._L = tuple(tuple(np.ascontiguousarray(Li, dtype=float) for Li in d.L) for d in self.designs)
        # 2. covariance: propagated under the noise model when one is given (or asked for)
        if track_covariance is None:
            track_covariance = noise is not None
        if track_covariance and noise is None:
            noise = default_noise(obs.system)
        if track_covariance and obs.hold != "innovation":
            raise InvalidArgument("track_covariance needs hold='innovation' (the exact error map)")
        self.noise = noise
        self.track_covariance = bool(track_covariance)
        self._keys: dict = {}
        self._R_held = None

    @classmethod
    def design_table(cls, system: Any, cycles: Any, *, robust: Any = None, delta: float = 0.99, **_: Any) -> Any:
        """The paper's design (:func:`~switchobs_core.design.lmi.design_table`)."""
        return design_table(system, cycles=cycles, robust=robust, delta=delta)

    # ------------------------------------------------------------------ protocol
    @property
    def source(self) -> str:
        return "table"

    def reset(self, obs: Any) -> None:
        self._R_held = None

    def fuses(self, obs: Any) -> bool:
        return False

    def steps_covariance(self) -> bool:
        return True

    def covariance(self, obs: Any) -> np.ndarray | None:
        return None if obs._P is None else obs._P.copy()

    def held_noise(self, obs: Any, e: Any) -> np.ndarray | None:
        """``(Gamma L) R (Gamma L)'``: the held sample's noise over the step (innovation hold)."""
        if obs._entry_L and self._R_held is not None:
            return e.GL @ self._R_held @ e.GL.T
        return None

    def depart(self, obs: Any, why: str) -> None:
        return None

    def _gain_key(self, obs: Any, channel: int, rows: Any) -> tuple:
        """ZOH cache key of channel ``channel`` with output rows ``rows`` under the current design."""
        di = obs.design_index
        ck = (di, channel, rows)
        key = self._keys.get(ck)
        if key is not None:
            return key
        Ci = obs.C[channel - 1]
        Li = self._L[di][channel - 1]
        if rows is not None:
            Ci = Ci[list(rows), :]
            Li = Li[:, list(rows)]
        key = ck
        if obs.hold == "innovation":
            obs._cache.register(key, obs.A, Li, obs.B, C=Ci)
        else:
            obs._cache.register(key, obs.A - Li @ Ci, Li, obs.B)
        obs._Crows[key] = Ci
        self._keys[ck] = key
        return key

    def sample(self, obs: Any, t: float, dt: float, channel: int, y: np.ndarray, rows: tuple | None) -> None:
        """Hold the sample's innovation (or the sample) with the gain of the current design."""
        p = y.size
        if t < obs._blind_until:     # dead time after the switch: no gain (module docstring)
            rows, y, p = (), y[:0], 0
        key = obs._key = self._gain_key(obs, channel, rows)
        Cr = obs._Crows[key]
        obs._y = y - Cr @ obs._x if obs.hold == "innovation" else y
        if obs._bound is not None:    # rounding of nu = y - C x_hat, and of the data y itself
            obs._bound.hold(Cr, math.sqrt(float(obs._x @ obs._x)), y, channel, p)
        obs._entry_L = True
        if obs._P is not None:
            self._R_held = obs.noise.R(channel, rows)
