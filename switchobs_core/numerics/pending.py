"""A step's set whose n x n assembly waits for a reader of the whole matrix
(:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.pending`): the screening reads a prior's blocks
and trace in O(p^2 + n), and a Kalman sample's step takes its product (:meth:`PendingSet.take`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["PendingSet", "assembled"]


class PendingSet:
    """A step's set ``S'`` whose n x n assembly waits for a reader of the whole matrix
    (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.pending`): :meth:`block` and :attr:`trace` read it
    in O(p^2 + n), :meth:`full` assembles it once; every read gives the doubles of the eager assembly. Its product
    ``Z`` may be handed over once before (:meth:`take`: a step that starts from the same product);
    a later read forms ``Z`` again (``remake``)."""

    __slots__ = ("_ell", "_Z", "_plan", "_S", "_remake", "tr", "trace", "kept")

    def __init__(self, ell: Any, Z: np.ndarray, plan: tuple,
                 remake: Callable[[], np.ndarray] | None) -> None:
        self._ell, self._Z, self._plan, self._S, self._remake = ell, Z, plan, None, remake
        #: Kept for a taker (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.keep_product`): :meth:`full`
        #: assembles a copy of ``Z``.
        self.kept = False
        #: ``trace S'``, the sum of its diagonal as computed (numpy's plan: as ``np.trace``; the kernel's
        #: ``open_plan``: in index order, another rounding of the same sum), and that rounded up (the
        #: ellipsoid's ``tr``, an upper bound whatever the order).
        self.trace, self.tr = plan[4], plan[5]

    def _product(self) -> np.ndarray:
        if self._Z is None:
            self._Z = self._remake()
        return self._Z

    def full(self) -> np.ndarray:
        """``S'`` (n x n, assembled at the first call; read-only)."""
        if self._S is None:
            Z = self._product()
            if self.kept:       # Z stays for the taker
                Z = Z.copy(order="K")
            else:
                self._Z = None
            self._S = self._ell._apply(Z, self._plan)[0]
        return self._S

    def block(self, cols: np.ndarray) -> np.ndarray:
        """``S'[np.ix_(cols, cols)]`` (a new array)."""
        if self._S is not None:
            return self._S[cols[:, None], cols]
        return self._ell._block(self._product(), self._plan, cols)

    def take(self) -> np.ndarray | None:
        """The product ``Z``, handed over once (the taker may overwrite it), or None when it is gone
        (assembled in place, or taken) or could not be formed again."""
        if self._Z is None or self._remake is None:
            return None
        Z, self._Z = self._Z, None
        return Z


def assembled(s: Any) -> Any:
    """``s.full()`` of a :class:`PendingSet`, else ``s`` (an array, a float, None)."""
    return s.full() if isinstance(s, PendingSet) else s
