"""The prior at a sample's time, computed once and shared by everything that reads it.

Before the observer takes a sample at ``t`` several readers ask for what :meth:`update
<switchobs_core.runtime.observer.SwitchedObserver.update>` starts from: the innovation test reads
the prediction and the rigorous sets (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior`),
the bias test the held prediction again and the prior covariance's block on the states its rows
see (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.predict`,
:meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior_covariance`), a re-attribution
every channel's reading of the same sample. Each is a function of the observer's state and ``t``
only, so :class:`PriorCache` keeps them for one time: the held step ``(entry, x_hat(t), rho)``,
the sets, and the covariance's blocks by columns (the whole covariance is not kept: it is a
view of the table's matrix, or n x n). The sample's own step at ``t`` takes the held step (the
estimate is propagated once per sample); the sets and the LMI family's prior covariance are taken by
their owners' own memos (``RoundingBound.step``, ``LmiGains.stepped``).

What it is keyed by (:meth:`PriorCache.at`): ``t`` and the observer's time, compared by value; the
estimate array by identity (every change of the estimate makes a new array, and the cache holds
the one it was computed from, so an identity is never reused); and the versions of the two
owners of the rest of the state: the published bounds' sets
(:attr:`~switchobs_core.runtime.error_bounds.ErrorBounds.version`: a sample, a step, a reset, a
restart, a withdrawal) and the held input (:attr:`~switchobs_core.runtime.held_input.HeldInput.version`:
a change ahead, a reset), and the Kalman table's ``missing`` setting. Any other time, any change of
state: nothing is served. The family's state (the covariance, the Kalman table's position) changes
only with a sample, a reset or a set state, each of which changes the key (a new estimate array, or
the sets' version). An estimate a caller writes into in place
(``update`` returns the observer's own array) is outside this, as it is outside every other step.

A hit serves the very objects computed at the miss: the same doubles (read-only; the prediction
is copied for each reader). The rows a reader tests are not part of the key: the sets and the
prediction do not depend on them, and a block is kept per columns.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PriorCache"]


class PriorCache:
    """The prior at one time (module docstring): :attr:`step` ``(entry, x_hat, rho)`` of the held
    step, :attr:`sets` (what ``ErrorBounds.sets`` gave), and the prior covariance's blocks by
    columns (:meth:`block`, :meth:`keep_block`: copies, a reader may write into its own)."""

    __slots__ = ("_key", "step", "sets", "_blocks")

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget everything (the next :meth:`at` starts afresh)."""
        self._key: tuple | None = None
        self.step: tuple | None = None
        self.sets: tuple | None = None
        self._blocks: dict = {}

    def at(self, t: float, now: float, x: np.ndarray, *versions: int) -> PriorCache:
        """The cache for the time ``t`` of an observer at ``now`` with estimate ``x`` and the state
        ``versions``: kept when all are those of the entries held, else emptied first."""
        k = self._key
        if k is None or k[0] != t or k[1] != now or k[2] is not x or k[3] != versions:
            self.clear()
            self._key = (t, now, x, versions)
        return self

    def block(self, cols: np.ndarray) -> np.ndarray | None:
        """A copy of the covariance's block kept for the columns ``cols``, or None."""
        if not self._blocks:        # none kept at this time (one reader a sample): no key to make
            return None
        hit = self._blocks.get((cols.dtype, cols.tobytes()))
        return None if hit is None else hit.copy()

    def keep_block(self, cols: np.ndarray, P: np.ndarray | None) -> np.ndarray | None:
        """Keep a copy of ``P``, the block for ``cols`` (None: nothing kept); returns ``P``."""
        if P is not None:
            self._blocks[(cols.dtype, cols.tobytes())] = np.array(P, dtype=float, copy=True)
        return P
