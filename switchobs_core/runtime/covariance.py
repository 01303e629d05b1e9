"""The error covariance through one exact step (Joseph-free: the step's error map is exact).

.. math::

    P \\leftarrow E P E' + Q_d(dt) + (\\Gamma L) R (\\Gamma L)'

with ``E`` the step's error map (:mod:`switchobs_core.numerics.propagation`: ``e^{A dt} -
Gamma_A L C`` with a held innovation, e:switched_observer; ``e^{A dt}`` with nothing held),
``Q_d`` the van Loan discretisation of the process intensity ``Q_c``
(:class:`~switchobs_core.design.riccati.DiscretizationCache`) and the last term the held
measurement noise driven through ``Gamma L`` (LMI gains, innovation hold; a Kalman family has
none: its correction follows at the sample). The gain families keep their covariance with it; the
Kalman families keep a factor of it (``P = L L'``, :meth:`CovarianceStep.factor_step`, the
square-root form of :mod:`switchobs_core.runtime.families.online`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg.lapack import dtrcon as _dtrcon

from ..bounds.kalman_map import sparse_transition
from ..design.riccati import DiscretizationCache
from ..numerics.kalman_step import psd_sqrt, symmetrize
from ..numerics.propagation import DEFAULT_DT_RESOLUTION

__all__ = ["CovarianceStep", "set_entries", "CHOLESKY_RCOND"]

#: Smallest reciprocal condition (LAPACK's 1-norm estimate) of the Cholesky factor of a predicted
#: covariance that :meth:`CovarianceStep.factor_step` keeps (the covariance's condition is its square:
#: about 1e12); below it the exact square root is taken instead.
CHOLESKY_RCOND = 1e-6


class CovarianceStep:
    """``P`` through the observer's steps under a noise model (module docstring).

    ``CovarianceStep(A, B, noise, dt_resolution)``; :meth:`step` is the propagation the family
    keeps, :meth:`prior` the one reported without keeping it.
    """

    def __init__(self, A: np.ndarray, B: np.ndarray, noise: Any, dt_resolution: float | None) -> None:
        self._dcache = DiscretizationCache(A, B, noise.Q_c, dt_resolution=dt_resolution or DEFAULT_DT_RESOLUTION)
        self._qs: dict[int, tuple] = {}       # id(Q_d) -> (Q_d, its square root or None for Q_d = 0)

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

    def factor_step(self, L: np.ndarray, e: Any, dt: float) -> np.ndarray:
        """:meth:`step` in square-root form, for a Kalman family (nothing held): from a factor ``L`` of
        ``P`` (``P = L L'``) a factor of ``P^- = E P E' + Q_d(dt)``.

        The Cholesky factor of ``P^-`` formed from ``E L`` when it is well conditioned (LAPACK's
        estimate of its reciprocal condition at least :data:`CHOLESKY_RCOND`: ``P^-``'s condition
        within about 1e12, the range :mod:`switchobs_core.design.precision` accepts, with four
        digits or more in its smallest direction), an n x n triangle; otherwise the
        exact square root ``[E L, Q_d^{1/2}]`` (n x 2n, as
        :func:`~switchobs_core.numerics.kalman_step.sqrt_predict`), which the next correction's QR
        compresses, with ``Q_d^{1/2}`` kept with its cached ``Q_d`` (none for ``Q_d = 0``). ``E L``
        is taken in factors when ``e^{A dt}`` is sparse."""
        _, _, Q_d = self._dcache.get(dt)
        sp = sparse_transition(e) if e.E is e.Phi else None
        EL = np.asarray(sp.csr @ L) if sp is not None else e.E @ L
        try:
            C = np.linalg.cholesky(EL @ EL.T + Q_d)
            if float(_dtrcon(C, norm="1", uplo="L")[0]) >= CHOLESKY_RCOND:
                return C
        except np.linalg.LinAlgError:
            pass
        hit = self._qs.get(id(Q_d))
        if hit is None or hit[0] is not Q_d:
            if len(self._qs) >= 2 * self._dcache.maxsize:
                self._qs.clear()
            hit = self._qs[id(Q_d)] = (Q_d, psd_sqrt(Q_d) if np.any(Q_d) else None)
        return EL if hit[1] is None else np.hstack([EL, hit[1]])

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
