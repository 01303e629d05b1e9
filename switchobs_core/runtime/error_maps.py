"""The error maps a sample applies, and how each enters ``Phi`` and the rigorous bound.

A gain family returns the maps it applied in its :class:`~switchobs_core.runtime.families.base.Correction`
(the observer's own propagation step is one too); the observer applies each, in order, with
``m.apply(transition, bound, channel)``: the map into ``Phi``
(:class:`~switchobs_core.runtime.transition.Transition`) and the step of the bound's ellipsoids
with the map's residual (:class:`~switchobs_core.bounds.rigorous.RoundingBound`; the residuals
are those of :mod:`switchobs_core.numerics.rounding`, steps 2-6). Each map carries what its
residual needs: the estimates before and after it, the data, the innovation.

:class:`ZohMap`
    one exact propagation step ``x <- e^{A dt} x + Gamma_A (B u + L nu)`` (e:switched_observer),
    error map ``E`` of the ZOH cache entry (``e^{A dt} - Gamma_A L C`` with a held innovation).
:class:`CorrectionMap`
    a Kalman correction ``x^+ = x^- + K (y - H x^-)`` at the sample, error map ``I - K H``.
:class:`FusedMap`
    a Kalman sample's prediction and correction in one map, ``(I - K H) e^{A dt}``
    (:class:`~switchobs_core.bounds.kalman_map.KalmanMap`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

__all__ = ["CorrectionMap", "FusedMap", "ZohMap", "apply_zoh", "norm", "zoh_step"]


def norm(x: np.ndarray) -> float:
    """``||x||_2`` of a vector (one dot product)."""
    return math.sqrt(float(x @ x))


def zoh_step(e: Any, x: np.ndarray, v: np.ndarray | None, u: np.ndarray | None) -> np.ndarray:
    """``x(t + dt) = e^{M dt} x + Gamma_M L v + Gamma_M B u`` over the ZOH cache entry ``e``, with
    the held ``v`` (innovation or sample; None: no gain held) and input ``u`` (None: zero)
    (e:switched_observer, sampled). A new array."""
    x1 = e.Phi @ x
    if v is not None:
        x1 += e.GL @ v
    if u is not None:
        x1 += e.GB @ u
    return x1


class ZohMap(NamedTuple):
    """One propagation step: the ZOH cache entry ``e`` over ``dt`` from ``x0`` to ``x1``, with the
    held ``v`` and ``u`` of :func:`zoh_step`; its error map is ``e.E``."""

    e: Any
    dt: float
    x0: np.ndarray
    x1: np.ndarray
    v: np.ndarray | None
    u: np.ndarray | None

    def apply(self, phi: Any, bound: Any, channel: int) -> None:
        """``Phi <- E Phi``; the bound's step (:func:`apply_zoh`)."""
        apply_zoh(phi, bound, self.e, self.dt, self.x0, self.x1, self.v, self.u)


def apply_zoh(phi: Any, bound: Any, e: Any, dt: float, x0: np.ndarray, x1: np.ndarray, v: np.ndarray | None,
              u: np.ndarray | None, extra: float = 0.0) -> None:
    """A :class:`ZohMap`'s ``Phi <- E Phi`` and the bound's step with the exponential's, the
    quantum's and the products' residual (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.step`),
    without forming the map (the observer's own steps); ``extra``: the residual of an input changed
    within the step (:mod:`switchobs_core.runtime.held_input`)."""
    phi.hold(e.E)
    if bound is not None:
        bound.step(e, dt, x0, x1, v, u, extra)


class CorrectionMap(NamedTuple):
    """A Kalman correction ``x^+ = x^- + K nu``, ``nu = y - H x^-``, with its error map ``I - K H``
    (``identity`` the n x n ``I``)."""

    K: np.ndarray
    H: np.ndarray
    identity: np.ndarray
    y: np.ndarray
    nu: np.ndarray
    x_minus: np.ndarray
    x_plus: np.ndarray

    def apply(self, phi: Any, bound: Any, channel: int) -> None:
        """``Phi <- (I - K H) Phi``; the bound's correction with the residual of the products
        ``H x^-`` and ``K nu`` and of the data (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.correct`)."""
        K, H, y, nu = self.K, self.H, self.y, self.nu
        phi.hold(K, H)
        if bound is not None and not bound.withdrawn:
            M = self.identity - K @ H
            fK, fH, _ = bound.gain_norms(K, H)
            rho = bound.rho_correct(fK, fH, self.x_minus, y, nu, self.x_plus)
            bound.w = bound.stamp_error(H, self.x_minus) if bound.tolerance else 0.0
            bound.correct(M, rho, K, H, y.size, channel)


class FusedMap(NamedTuple):
    """A Kalman sample in one map: ``x^- = e^{A dt} x0``, ``x^+ = x^- + K (y - H x^-)``, error map
    ``m = (I - K H) e^{A dt}`` (a :class:`~switchobs_core.bounds.kalman_map.KalmanMap` with the
    step's entry ``m.e``, gain ``m.K`` and rows ``m.H``)."""

    m: Any
    dt: float
    x0: np.ndarray
    x_minus: np.ndarray
    x_plus: np.ndarray
    y: np.ndarray
    nu: np.ndarray
    phase: int = -1

    def apply(self, phi: Any, bound: Any, channel: int) -> None:
        """``Phi <- m Phi`` (``m`` formed only if ``Phi`` or the bound reads it); the bound's fused
        step: the prediction's residual through ``||I - K H||`` plus the correction's
        (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.fused`), or with the phase bound
        (:mod:`switchobs_core.bounds.phase_bound`; ``phase`` the table's periodic phase, -1 for the
        start-up) its scalars where they hold."""
        m, y = self.m, self.y
        phi.hold(m)
        pb = None if bound is None else bound.phase
        if pb is not None and not bound.withdrawn and pb.sample(bound, self, channel):
            return
        if bound is not None and not bound.withdrawn:
            if pb is None and bound.fused_sample(self, channel):     # a dense map, no shaped term
                return
            bound.w = bound.stamp_error(m.H, self.x_minus, bound.prior_beta(m.e, self.dt, self.x0, self.x_minus,
                                                                              None)) if bound.tolerance else 0.0
            xs, xs1, xsp = bound.fused_norms(self.x0, self.x_minus, self.x_plus)
            rc = bound.rho_correct(m.fK, m.fH, self.x_minus, y, self.nu, None, xs1, xsp)
            bound.fused(m.e, self.dt, m, self.x0, self.x_minus, rc, m.K, y.size, channel, norms=(xs, xs1))
            if pb is not None:
                pb.enter(bound, self)
