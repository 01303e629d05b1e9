r"""Missing samples on a locked Kalman table's grid: the stored gains kept, the covariance exact.

A table locked at sample ``k0`` has the stored posterior ``P^+_{k0}`` as its real covariance
(:mod:`switchobs_core.runtime.families.kalman`). A sample ``j`` of the grid that does not come
(no correction) leaves its prior ``S_j`` as its posterior, and the stored gain
``K_j = S_j H_j' W_j^{-1}`` of the phase, ``W_j = H_j S_j H_j' + R_j``, splits that prior as

.. math::

    S_j = P^+_j + K_j W_j K_j'

(the Joseph form with the optimal gain: ``P^+_j = S_j - K_j W_j K_j'``). With the stored gains
applied from there on, the real covariance is the stored one plus a term of low rank, ``U U'``,
``U`` (n x r) a deviation of the posterior carried sample by sample:

- a missing sample ``j``: ``U <- [U, K_j W_j^{1/2}]`` (``W_j^{1/2}`` its Cholesky factor);
- the prediction over one sample period: ``U <- e^{A dt} U`` (``Q_d`` is in the stored prior:
  ``e (P^+ + U U') e' + Q_d = S + (e U)(e U)'``);
- a sample with the stored gain ``K`` and rows ``H``: ``U <- (I - K H) U``, since the Joseph
  form holds for any gain: ``(I - K H)(S + U U')(I - K H)' + K R K' = P^+ + ((I - K H) U)((I -
  K H) U)'``.

A step over ``g`` periods (``g - 1`` samples missing) is ``g`` of these predictions with a missing
sample between each two. Each costs ``O(nnz(e^{A dt}) r + n p r)`` (``e^{A dt}`` in its sparse
form where it is sparse, :func:`~switchobs_core.bounds.kalman_map.sparse_transition`) where the
recursion online costs ``O(n^3)``; ``U`` is compressed to n columns (one QR of ``U'``, ``U U'``
unchanged) once it holds ``2 n``.

Retire. At a sample whose prior deviation ``V`` satisfies ``||V_i||^2 <= rtol S_ii`` on every row
(``S`` the stored prior, ``rtol`` the table's ``relock_rtol``), ``|V V'|_ij <= ||V_i|| ||V_j|| <=
rtol sqrt(S_ii S_jj)`` (Cauchy-Schwarz): the difference is within what the re-lock test accepts
after a departure, and ``U`` is dropped; from there the stored covariance is published, as after a
re-lock. The test leaves room for its roundings: a relative ``2 (r + 4) eps`` on the row norms.

Too far. The stored gains suit a covariance near the stored one. Where missing samples leave a
prior deviation larger than :data:`GAP_MAX` times the stored prior on some diagonal entry
(``||V_i||^2 > GAP_MAX S_ii``: a run of missing samples, or one early in the start-up, where the
stored prior is far below ``P0``), the table departs instead and the recursion runs online from
the real covariance (``S + V V'`` at that sample), as for any other departure. One missing sample
never does: its deviation ``K W K' = S - P^+`` is below ``S`` (measured on the paper's system: a
missing sample at 0.04 s left the stored-gain covariance 480x the filter's, against its largest entry).

The estimate with the stored gains is not the optimal Kalman estimate while a gap's ``U`` lasts
(the optimal gain would use ``S + V V'``); its covariance is exact, so the chi-square gate, the
innovation and bias tests and the published covariance stay right. The accuracy cost is measured
in bench/RESULTS.md and docs/concepts/gain-families.md.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ...bounds.kalman_map import sparse_transition

__all__ = ["GAP_MAX", "GapDeviation"]

#: Largest prior deviation after missing samples, in units of the stored prior's diagonal, served
#: with the stored gains (module docstring, too far).
GAP_MAX = 10.0

_EPS = float(np.finfo(float).eps)


class GapDeviation:
    """The deviation ``U`` of a locked table's covariance after missing samples (module docstring).

    ``GapDeviation(kd, step, rtol)``: ``kd`` the :class:`~switchobs_core.table.kalman.KalmanDesign`,
    ``step()`` the ZOH cache entry of one sample period (``e^{A dt}`` of the design's step).

    Attributes
    ----------
    U : ndarray or None
        The posterior deviation after the last sample (n x r), None when there is none.
    gaps, missed, retired : int
        Samples that followed missing ones on the table, the missing samples, and deviations
        retired (since the last reset).
    """

    def __init__(self, kd: Any, step: Callable[[], Any], rtol: float) -> None:
        self.kd, self._step, self.rtol = kd, step, float(rtol)
        self._cols: dict = {}
        self.reset()

    def reset(self) -> None:
        self.U: np.ndarray | None = None
        self._memo: tuple | None = None
        self.gaps = self.missed = self.retired = 0

    def clear(self) -> None:
        """Drop ``U`` (the family's covariance is its own from here: a departure)."""
        self.U = None
        self._memo = None

    def entry(self, k: int) -> Any:
        """The stored sample ``k`` of the grid (start-up, then the periodic pattern)."""
        kd = self.kd
        return kd.startup[k] if k < len(kd.startup) else kd.periodic[k % kd.pattern.K]

    def missing_columns(self, k: int) -> np.ndarray:
        """``K_k W_k^{1/2}`` of sample ``k`` (n x p, cached per phase): its posterior is its prior
        less ``(K W^{1/2})(K W^{1/2})'``, so a missing sample adds these columns to ``U``."""
        kd = self.kd
        key = (True, k) if k < len(kd.startup) else (False, k % kd.pattern.K)
        G = self._cols.get(key)
        if G is None:
            ent = self.entry(k)
            H = kd.H(ent.channel, ent.rows)
            cols = np.flatnonzero(np.any(H != 0, axis=0))
            Hc = H[:, cols]
            W = Hc @ ent.P_block(cols) @ Hc.T + kd.noise.R(ent.channel, ent.rows)
            G = self._cols[key] = ent.K @ np.linalg.cholesky(0.5 * (W + W.T))
        return G

    def _propagate(self, V: np.ndarray) -> np.ndarray:
        e = self._step()
        sp = sparse_transition(e)
        return e.Phi @ V if sp is None else np.asarray(sp.csr @ V)

    def prior(self, last_k: int, k: int) -> np.ndarray | None:
        """The prior deviation ``V`` at sample ``k > last_k`` (the real prior is ``S_k + V V'``),
        the samples between missing; None when there is none (``U`` None and no sample missing)."""
        memo = self._memo
        if memo is not None and memo[0] == last_k and memo[1] == k:
            return memo[2]
        V = self.U
        for j in range(last_k + 1, k + 1):
            if V is not None:
                V = self._propagate(V)
            if j < k:
                G = self.missing_columns(j)
                V = G if V is None else np.hstack((V, G))
        self._memo = (last_k, k, V)
        return V

    def corrected(self, last_k: int, k: int, K: np.ndarray, H: np.ndarray, S_diag: Callable[[], np.ndarray]) -> None:
        """Sample ``k`` corrected with the gain ``K`` on rows ``H``: ``U <- (I - K H) V`` of the
        prior deviation ``V`` (counting the missing samples), or None when ``V`` passes the retire
        test against the diagonal ``S_diag()`` of the stored prior (module docstring)."""
        if k > last_k + 1:
            self.gaps += 1
            self.missed += k - last_k - 1
        V = self.prior(last_k, k)
        self._memo = None
        if V is None:
            self.U = None
            return
        if self.retires(V, S_diag()):
            self.U = None
            self.retired += 1
            return
        cols = np.flatnonzero(np.any(H != 0, axis=0))
        U = V - K @ (H[:, cols] @ V[cols])
        if U.shape[1] >= 2 * U.shape[0]:
            U = np.linalg.qr(U.T, mode="r").T        # U U' = R' R: n columns
        self.U = U

    def too_far(self, last_k: int, k: int, S_diag: np.ndarray) -> bool:
        """Whether the prior deviation at sample ``k`` exceeds :data:`GAP_MAX` times the stored
        prior's diagonal ``S_diag`` on some entry (module docstring, too far)."""
        V = self.prior(last_k, k)
        return V is not None and bool(np.any(np.einsum("ij,ij->i", V, V) > GAP_MAX * np.abs(S_diag)))

    def retires(self, V: np.ndarray, S_diag: np.ndarray) -> bool:
        """``||V_i||^2 <= rtol S_ii`` on every row with room for the roundings (module docstring)."""
        v = np.einsum("ij,ij->i", V, V) * (1.0 + 2.0 * (V.shape[1] + 4) * _EPS)
        return bool(np.all(v <= self.rtol * np.abs(S_diag) * (1.0 - 4.0 * _EPS)))
