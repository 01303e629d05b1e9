"""The error covariance through one exact step (Joseph-free: the step's error map is exact).

.. math::

    P \\leftarrow E P E' + Q_d(dt) + (\\Gamma L) R (\\Gamma L)'

with ``E`` the step's error map (:mod:`switchobs_core.numerics.propagation`: ``e^{A dt} -
Gamma_A L C`` with a held innovation, e:switched_observer; ``e^{A dt}`` with nothing held),
``Q_d`` the van Loan discretisation of the process intensity ``Q_c``
(:class:`~switchobs_core.design.riccati.DiscretizationCache`) and the last term the held
measurement noise driven through ``Gamma L`` (LMI gains, innovation hold; a Kalman family has
none: its correction follows at the sample). The gain families keep their covariance with it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..bounds.kalman_map import sparse_transition
from ..design.riccati import DiscretizationCache
from ..numerics.kalman_step import symmetrize
from ..numerics.propagation import DEFAULT_DT_RESOLUTION

__all__ = ["CovarianceStep", "set_entries"]


class CovarianceStep:
    """``P`` through the observer's steps under a noise model (module docstring).

    ``CovarianceStep(A, B, noise, dt_resolution)``; :meth:`step` is the propagation the family
    keeps, :meth:`prior` the one reported without keeping it.
    """

    def __init__(self, A: np.ndarray, B: np.ndarray, noise: Any, dt_resolution: float | None) -> None:
        self._dcache = DiscretizationCache(A, B, noise.Q_c, dt_resolution=dt_resolution or DEFAULT_DT_RESOLUTION)

    def step(self, P: np.ndarray, e: Any, dt: float, held_noise: np.ndarray | None = None) -> np.ndarray:
        """``E P E' + Q_d(dt)`` (+ ``held_noise``) for the ZOH cache entry ``e``, symmetrised; the
        open-loop map of a Kalman family in factors when ``e^{A dt}`` is sparse
        (:func:`~switchobs_core.bounds.kalman_map.sparse_transition`)."""
        _, _, Q_d = self._dcache.get(dt)
        sp = sparse_transition(e) if e.E is e.Phi else None
        P = (sp.sandwich(P) if sp is not None else e.E @ P @ e.E.T) + Q_d
        if held_noise is not None:
            P += held_noise
        return symmetrize(P)

    def prior(self, P: np.ndarray, e: Any, dt: float, held_noise: np.ndarray | None = None) -> np.ndarray:
        """The same with dense products (the prior a consistency test reads)."""
        _, _, Q_d = self._dcache.get(dt)
        P = e.E @ P @ e.E.T + Q_d
        if held_noise is not None:
            P += held_noise
        return symmetrize(P)


def set_entries(P: np.ndarray, indices: Any, variances: dict) -> np.ndarray:
    """A copy of ``P`` with row and column ``i`` zeroed and ``P[i, i] = variances[i]`` (default
    the previous ``P[i, i]``) for every ``i`` in ``indices``: the set entries' errors are then
    uncorrelated with the others (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate`)."""
    P = P.copy()
    for i in indices:
        var = float(variances.get(i, P[i, i]))
        P[i, :] = 0.0
        P[:, i] = 0.0
        P[i, i] = var
    return P
