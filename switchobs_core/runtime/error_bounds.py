"""The bounds of the observer's error that it publishes, read at a time ``t``.

``hold="innovation"`` with ``rounding_bound``
    the rigorous ellipsoids of :class:`~switchobs_core.bounds.rigorous.RoundingBound` (the exact
    bound for noise-free samples and, with a declared ``noise_max``, the noise bound), rounding
    included (:mod:`switchobs_core.numerics.rounding`). At the last sample's time their bounds are
    read once per sample (by the eigenvalue problem, or amortised in O(n^2) between verified
    anchors, :mod:`switchobs_core.bounds.read`); at a later time the sets are propagated over the
    step without being kept.
``hold="measurement"``
    ``||Phi(t, t0)|| e0``: the error-to-error part of the joint transition, in exact arithmetic
    (:class:`~switchobs_core.runtime.transition.Transition`).
otherwise
    no bound (``inf``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..bounds.read import AMORTISED_MIN_N
from ..bounds.rigorous import RoundingBound
from .transition import Transition

__all__ = ["ErrorBounds"]


class ErrorBounds:
    """The observer's published error bounds (module docstring).

    ``ErrorBounds(A, p_max, e0, noise_max, hold, rounding_bound, phi, disturbance=d)`` (``d`` a declared
    :class:`~switchobs_core.model.disturbance.Disturbance` or None); :attr:`rigorous` is the
    :class:`~switchobs_core.bounds.rigorous.RoundingBound` the error maps step (None when not kept);
    :attr:`version` counts the changes of the sets (:meth:`reset`, :meth:`restart`, :meth:`withdraw`,
    :meth:`changed`; :mod:`~switchobs_core.runtime.priors` keys on it).
    """

    def __init__(self, A: np.ndarray, p_max: int, e0: float | None, noise_max: Sequence[float] | None, hold: str,
                 rounding_bound: bool, phi: Transition, *, B: np.ndarray | None = None,
                 scale: np.ndarray | None = None, disturbance: Any = None) -> None:
        self.rigorous = (RoundingBound(A, p_max, e0, noise_max, B=B, scale=scale, disturbance=disturbance)
                         if hold == "innovation" and rounding_bound else None)
        self.n = A.shape[0]
        self._e0 = e0
        self._measurement = hold == "measurement"
        self._phi = phi
        self._last: tuple | None = None     # (amortised, (exact, noise)) of the last sample's sets
        self.version = 0

    def reset(self) -> None:
        """``S = e0^2 I``."""
        self.version += 1
        if self.rigorous is not None:
            self.rigorous.reset()
        self._last = None

    def restart(self, e: float) -> bool:
        """The rigorous sets restart as the ball of radius ``e`` (a bound that holds at the last
        sample's time, :mod:`switchobs_core.runtime.recertify`); False when no rigorous set is kept."""
        self.version += 1
        if self.rigorous is None:
            return False
        self.rigorous.restart(e)
        self._last = None
        return True

    def withdraw(self, why: str) -> None:
        """The rigorous sets are withdrawn with ``why`` (kept if they already are) until :meth:`reset` or
        :meth:`restart`: not propagated any more, their bounds ``inf``; for a caller that publishes no
        bound while it holds none (a restart starts them afresh, so nothing of the sets is lost)."""
        self.version += 1
        if self.rigorous is not None and not self.rigorous.withdrawn:
            self.rigorous.withdrawn = str(why) or "withdrawn by the caller"
            self._last = None

    def changed(self) -> None:
        """The sets changed (a sample, a step): their bounds are read again."""
        self.version += 1
        self._last = None

    def read(self, step: Any, dt: float, x: np.ndarray, xp: np.ndarray | None, v: np.ndarray | None,
             u: np.ndarray | None, amortised: bool | None, extra: float = 0.0) -> tuple[float, float | None]:
        """``(exact, noise)`` at ``dt`` after the last sample: ``step`` the ZOH cache entry over
        ``dt`` (None at the sample's time), ``x`` the estimate at the sample, ``xp`` the prediction
        at ``t`` (with the rigorous bound and a step), ``v`` and ``u`` what is held; ``amortised``
        None: from :data:`~switchobs_core.bounds.read.AMORTISED_MIN_N` states on; ``extra`` the residual
        of an input changed within the step (:mod:`switchobs_core.runtime.held_input`)."""
        b = self.rigorous
        if b is not None:       # rounding included (module switchobs_core.numerics.rounding)
            if amortised is None:
                amortised = self.n >= AMORTISED_MIN_N
            if step is None:    # the sets of the last sample: their bounds once per sample
                if self._last is None or self._last[0] != amortised:
                    self._last = (amortised, b.bounds(amortised=amortised))
                return self._last[1]
            if b.withdrawn:
                return b.bounds()
            if b.phase is not None and b.phase.j >= 0:      # the phase bound's scalars stay (bound_option)
                return b.phase.later(b, step, dt, x, xp, v, u, extra)
            return b.bounds(*b.propagated(step, dt, x, xp, v, u, extra))
        if self._measurement:   # the error-to-error part, exact arithmetic
            Phi = self._phi.read()
            if self._e0 is None:    # no initial error bound: no bound (re-certification needs the ellipsoids)
                return math.inf, None
            return float(np.linalg.norm(Phi if step is None else step.E @ Phi, 2) * self._e0), None
        return math.inf, None   # rounding_bound=False: no bound is kept

    @property
    def withdrawn(self) -> str:
        """Why the rigorous bounds are withdrawn ("" while they hold; :mod:`switchobs_core.bounds.rigorous`)."""
        return "" if self.rigorous is None else self.rigorous.withdrawn

    def sets(self, step: Any, dt: float, x: np.ndarray, xp: np.ndarray, v: np.ndarray | None,
             u: np.ndarray | None, extra: float = 0.0, *, lazy: bool = False) -> tuple[Any, Any]:
        """The shape matrices ``(S, S_noise or None)`` of the rigorous sets at ``t`` (arguments as
        :meth:`read`; copies at the sample's time, propagated after it by ``RoundingBound.propagated``, a
        sparse map in compressed rows: read-only, the sample's own step at ``t`` takes copies of them;
        ``lazy``: :class:`~switchobs_core.numerics.rounding.PendingSet` where the map is sparse)."""
        b = self.rigorous
        if b.withdrawn:         # no set is kept any more: the norm bounds say so
            return math.inf, None if b.ellv is None else math.inf
        if b.phase is not None and b.phase.j >= 0:      # norm bounds: the phase bound's scalars stay
            return b.phase.bounds() if step is None else b.phase.later(b, step, dt, x, xp, v, u, extra)
        if step is None:
            return b.ell.S.copy(), None if b.ellv is None else b.ellv.S.copy()
        return b.propagated(step, dt, x, xp, v, u, extra, lazy=lazy)
