"""The known input ``u`` the observer holds (e:system's ``B u`` under a zero-order hold), changed at
its own times between samples (a command's stamp).

The observer steps from one sample to the next in one exact step: its error map (e:switched_observer,
``e^{A dt} - Gamma_A L C`` with the innovation held) belongs to the whole interval, since the held
innovation is the sample's that started it. An input that changes inside the interval, at ``t_j``
from ``u_{j-1}`` to ``u_j``, adds the open-loop ZOH of the change to the estimate at ``t``:
``Gamma_M(t - t_j) B (u_j - u_{j-1})`` (``M`` the step's matrix; exact), and nothing to the error:
the plant receives the same input, so ``B u`` cancels. The products' floating-point rounding is the
one thing the bound gains (:meth:`HeldInput.add`'s residual:
:meth:`~switchobs_core.bounds.rigorous.RoundingBound.rho_input`, in balanced units).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["HeldInput"]


class HeldInput:
    """The input held at the observer's time (``u``, None: zero) and the changes after it
    (``changes``: ``(t_j, u_j)`` in time order, ``u_j`` None for zero). ``version`` counts the
    changes of either (:mod:`~switchobs_core.runtime.priors` keys on it)."""

    def __init__(self) -> None:
        self.version = 0
        self.reset()

    def reset(self) -> None:
        self.version += 1
        self.u: np.ndarray | None = None
        self.changes: list[tuple[float, np.ndarray | None]] = []

    @property
    def last(self) -> np.ndarray | None:
        """The input held after every change."""
        return self.changes[-1][1] if self.changes else self.u

    def pending(self, t: float) -> bool:
        """Whether a change lies before ``t`` (the step to ``t`` then adds it)."""
        return bool(self.changes) and self.changes[0][0] < t

    def change(self, t: float, u: np.ndarray | None) -> None:
        """Hold ``u`` from ``t`` on (``t`` not before the last change)."""
        self.version += 1
        self.changes.append((float(t), u))

    def add(self, x: np.ndarray, t: float, step: Callable[[float], Any],
            residual: Callable[[Any, float, np.ndarray, np.ndarray], float] | None) -> tuple[np.ndarray, float]:
        """``x`` (the step to ``t`` with ``u`` held, a new array) plus the changes before ``t``,
        each ``e.GB @ (u_j - u_{j-1})`` with ``e = step(t - t_j)`` (a ZOH cache entry of the step's
        key); and the sum of ``residual(e, t - t_j, d_j, x)`` over the changes, the rounding of
        these products and sums (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.rho_input`;
        0 with no change or no ``residual``)."""
        rho = 0.0
        prev = self.u
        for tj, uj in self.changes:
            if tj >= t:
                break
            d = (np.zeros_like(prev) if uj is None else uj) - (0.0 if prev is None else prev)
            e = step(t - tj)
            x += e.GB @ d
            if residual is not None:
                rho += residual(e, t - tj, d, x)
            prev = uj
        return x, rho

    def settle(self, t: float) -> None:
        """The observer is at ``t``: the changes up to ``t`` are held now."""
        self.version += 1
        while self.changes and self.changes[0][0] <= t:
            self.u = self.changes.pop(0)[1]
