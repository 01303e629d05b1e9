"""The observer's error transition ``Phi(t, t0)``: the product of the steps' error maps.

With innovation hold every step maps the error exactly, ``x_tilde(t_{k+1}) = E_k x_tilde(t_k)``
(``E_k = e^{A dt} - Gamma_A L_i C_i`` for a held innovation, ``(I - K H) e^{A dt}`` for a Kalman
sample; e:switched_observer), so ``Phi = E_k ... E_1`` and ``||x_tilde(t)|| <= ||Phi|| e0``.
With measurement hold ``Phi`` is the error-to-error part of the joint transition.

``Phi`` costs an n x n product per sample, so it is formed only for a reader: by default the
maps are held (references to cached matrices) and multiplied out at the first read, after which
``Phi`` is kept at every step; if it is not read within a budget of held maps it is no longer
kept and reading it raises (:class:`Transition`).
"""

from __future__ import annotations

import numpy as np

from ..exceptions import InvalidArgument

__all__ = ["Transition"]

#: Floating-point work (flops, about ``2 n^3`` per held map) a first read of ``Phi`` may cost: beyond
#: it (or beyond :data:`PENDING_BYTES` of held arrays) an unread ``Phi`` is no longer kept.
PENDING_FLOPS = 2**31
#: Bytes of distinct arrays the held maps may keep alive.
PENDING_BYTES = 64 << 20


class Transition:
    """``Phi(t, t0)`` of one observer run (module docstring).

    ``T = Transition(n, mode)`` with ``mode`` ``"kept"`` (formed at every step), ``"held"`` (maps
    held until the first read) or ``"off"`` (never formed); :meth:`reset` restarts at ``I``.
    """

    def __init__(self, n: int, mode: str) -> None:
        self.n = n
        self._init = mode
        #: Maps held before an unread ``Phi`` is dropped: about ``2^31 / (2 n^3)``, 256..65536.
        self.pending_max = int(min(max(PENDING_FLOPS // (2 * n ** 3), 256), 65536))
        self.reset()

    def reset(self) -> None:
        """``Phi = I``; nothing held; the mode of the construction."""
        self._Phi = np.eye(self.n)
        self._mode = self._init         # "kept", "held" (until read), "dropped", "off"
        self._pending: list = []        # error maps not yet multiplied into Phi
        self._pending_ids: set = set()
        self._pending_bytes = 0

    def read(self) -> np.ndarray:
        """``Phi`` with the held error maps multiplied in (in the order they were applied); from
        the first read on it is kept up to date at every step. The array is the transition's own.

        Raises
        ------
        InvalidArgument
            ``Phi`` is not kept (mode ``"off"``), or it was dropped unread.
        """
        if self._mode != "kept":
            if self._mode == "off":
                raise InvalidArgument("Phi is not kept (transition=False); construct the observer with "
                                      "transition=True to read it")
            if self._mode == "dropped":
                raise InvalidArgument(f"Phi was not read within {self.pending_max} samples of the reset and is no "
                                      "longer kept (its product costs O(n^3) per sample); construct the observer "
                                      "with transition=True to keep it")
            self._mode = "kept"
        Phi = self._Phi
        for K, H in self._pending:
            if H is None:
                Phi = K @ Phi
            else:
                Phi -= K @ (H @ Phi)
        self._Phi = Phi
        self._clear()
        return Phi

    def hold(self, K: np.ndarray, H: np.ndarray | None = None) -> None:
        """``Phi <- K Phi`` (``H`` None; ``K`` an n x n map, or anything with ``@`` and ``nbytes``
        such as a :class:`~switchobs_core.bounds.kalman_map.KalmanMap`) or
        ``Phi <- (I - K H) Phi``: now when kept, at the first read when held."""
        mode = self._mode
        if mode == "kept":
            self._Phi = K @ self._Phi if H is None else self._Phi - K @ (H @ self._Phi)
            return
        if mode != "held":
            return
        pending, ids = self._pending, self._pending_ids
        pending.append((K, H))
        if id(K) not in ids or H is not None and id(H) not in ids:     # a map not held yet (most samples repeat one)
            for X in (K, H):
                if X is not None and id(X) not in ids:
                    ids.add(id(X))
                    self._pending_bytes += X.nbytes
        if len(pending) > self.pending_max or self._pending_bytes > PENDING_BYTES:
            self._mode = "dropped"      # nobody read it: stop paying for it
            self._clear()

    def _clear(self) -> None:
        self._pending.clear()
        self._pending_ids.clear()
        self._pending_bytes = 0
