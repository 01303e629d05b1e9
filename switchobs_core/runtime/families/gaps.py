r"""Missing samples on a Kalman table's grid: the table stays the reference, the difference in low rank.

A table locked at sample ``k0`` has the stored posterior ``P^+_{k0}`` as its real covariance
(:mod:`switchobs_core.runtime.families.kalman`). A sample ``j`` of the grid that does not come
(no correction) leaves its prior ``S_j`` as its posterior, and the stored gain
``K_j = S_j H_j' W_j^{-1}`` of the phase, ``W_j = H_j S_j H_j' + R_j``, splits that prior as

.. math::

    S_j = P^+_j + K_j W_j K_j'

(the Joseph form with the optimal gain). So from there the real covariance is the stored one plus
a term of low rank, ``U U'``, ``U`` (n x r) a deviation of the posterior carried sample by sample:

- a missing sample ``j``: ``U <- [U, K_j W_j^{1/2}]`` (``W_j^{1/2}`` its Cholesky factor);
- the prediction over one sample period: ``U <- e^{A dt} U`` (``Q_d`` is in the stored prior:
  ``e (P^+ + U U') e' + Q_d = S + (e U)(e U)'``); a step over ``g`` periods is ``g`` of these
  with a missing sample between each two;
- a sample with rows ``H`` corrected with any gain ``K`` (stored gain ``K_s``, ``K_s W = S H'``)
  from the prior ``S + V V'``: the Joseph form is linear in the prior and
  ``(I - K H) S (I - K H)' + K R K' = P^+ + (K - K_s) W (K - K_s)'``, so
  ``U <- [(I - K H) V, (K - K_s) W^{1/2}]``.

The gain applied is the Kalman filter's own for the real prior, ``K* = (K_s W + V (H V)') (W + (H
V)(H V)')^{-1}`` (``P^- H' = S H' + V (H V)'``, ``H P^- H' + R = W + (H V)(H V)'``): the estimate
is the optimal filter's, the one the Riccati recursion online computes (rounded differently), at
``O(nnz(e^{A dt}) r + n p r)`` a sample (``e^{A dt}`` in its sparse form where it is sparse,
:func:`~switchobs_core.bounds.kalman_map.sparse_transition`) where the recursion costs ``O(n^3)``.
``U`` gains ``p`` columns a sample and is compressed to n (one QR of ``U'``, ``U U'`` unchanged)
once it holds ``2 n``. The rigorous bound takes the error map of the gain applied, as everywhere.

Retire. At a sample whose prior deviation ``V`` satisfies ``||V_i||^2 <= rtol S_ii`` on every row
(``S`` the stored prior, ``rtol`` the table's ``relock_rtol``), ``|V V'|_ij <= ||V_i|| ||V_j|| <=
rtol sqrt(S_ii S_jj)`` (Cauchy-Schwarz): the difference is within what the re-lock test accepts
after a departure, and ``U`` is dropped (tested at every :data:`RETIRE_EVERY`-th sample of a
deviation: a deviation kept longer is still exact); from there the stored gains serve and the stored
covariance is published, as after a re-lock (the same approximation). The test leaves room for
its roundings: a relative ``2 (r + 4) eps`` on the row norms.

Too far. A deviation past :data:`GAP_MAX` times the stored prior on some diagonal entry
(``||V_i||^2 > GAP_MAX S_ii``) would cancel more than six digits in ``(I - K H) V``; the table
departs there instead and the square-root recursion runs online from the real covariance (so
does a missing phase whose stored row fails its checksum, a corrupted file read lazily). The
largest seen on the 32-agent table with 10 % of the samples missing was 1.1e9 (the first sample
of an agent's residence missing in the start-up, while its prior was still near ``P0``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ...bounds.kalman_map import sparse_transition
from ...exceptions import GainTableError

__all__ = ["GAP_MAX", "GapDeviation"]

#: The retire test runs at every this many samples of a deviation (it spares nothing exact: a
#: deviation kept longer is still the real one).
RETIRE_EVERY = 8
#: Largest prior deviation after missing samples, in units of the stored prior's diagonal, served
#: on the table's grid (module docstring, too far).
GAP_MAX = 1e12

_EPS = float(np.finfo(float).eps)


class GapDeviation:
    """The deviation ``U`` of a table's covariance after missing samples (module docstring).

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
        self._W: dict = {}
        self._cols: dict = {}
        self.reset()

    def reset(self) -> None:
        self.U: np.ndarray | None = None
        self._memo: tuple | None = None
        self._since = 0             # corrections since the deviation appeared (the retire test's cadence)
        self.gaps = self.missed = self.retired = 0

    def clear(self) -> None:
        """Drop ``U`` (the family's covariance is its own from here: a departure)."""
        self.U = None
        self._memo = None
        self._since = 0

    def _key(self, k: int) -> tuple:
        kd = self.kd
        return (True, k) if k < len(kd.startup) else (False, k % kd.pattern.K)

    def entry(self, k: int) -> Any:
        """The stored sample ``k`` of the grid (start-up, then the periodic pattern)."""
        kd = self.kd
        return kd.startup[k] if k < len(kd.startup) else kd.periodic[k % kd.pattern.K]

    def _innovation(self, k: int, channel: int, rows: tuple | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(W, W^{1/2}, cols)`` of the stored prior of sample ``k`` on ``channel``'s ``rows``:
        ``W = H S H' + R`` (from the block of ``S`` on the states ``cols`` the rows see; cached)."""
        key = (self._key(k), channel, rows)
        hit = self._W.get(key)
        if hit is None:
            kd = self.kd
            H = kd.H(channel, rows)
            cols = _seen(H)
            Hc = H[:, cols]
            W = Hc @ self.entry(k).P_block(cols) @ Hc.T + kd.noise.R(channel, rows)
            W = 0.5 * (W + W.T)
            hit = self._W[key] = (W, np.linalg.cholesky(W), cols)
        return hit

    def missing_columns(self, k: int) -> np.ndarray:
        """``K_k W_k^{1/2}`` of sample ``k`` (n x p, cached per phase): its posterior is its prior
        less ``(K W^{1/2})(K W^{1/2})'``, so a missing sample adds these columns to ``U``."""
        key = self._key(k)
        G = self._cols.get(key)
        if G is None:
            ent = self.entry(k)
            G = self._cols[key] = ent.K @ self._innovation(k, ent.channel, ent.rows)[1]
        return G

    def _propagate(self, V: np.ndarray) -> np.ndarray:
        """``e^{A dt} V`` (sparse where ``e^{A dt}`` is)."""
        e = self._step()
        sp = sparse_transition(e)
        if sp is None:
            return e.Phi @ V
        return sp.matmat(V)

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

    def too_far(self, last_k: int, k: int, S_diag: np.ndarray) -> str:
        """Why the prior deviation at sample ``k`` is too far (module docstring: past
        :data:`GAP_MAX` times the stored prior's diagonal ``S_diag`` on some entry; or a missing
        phase's stored row fails its checksum), "" if it is not."""
        try:
            V = self.prior(last_k, k)
        except GainTableError as err:
            return f"a deviation the table cannot give ({err})"
        if V is None:
            return ""
        vv, s = np.einsum("ij,ij->i", V, V), np.abs(S_diag)
        over = np.flatnonzero(~(vv <= GAP_MAX * s))     # NaN too; a zero S_ii with V_i != 0 is past any ratio
        if not over.size:
            return ""
        i = int(over[0])
        return f"a covariance {vv[i] / s[i] if s[i] > 0 else np.inf:.3g} times the Kalman table's in entry {i} " \
               f"(more than {GAP_MAX:g})"

    def correct(self, last_k: int, k: int, K: np.ndarray, H: np.ndarray, channel: int, rows: tuple | None,
                S_diag: Callable[[], np.ndarray]) -> np.ndarray:
        """The gain of sample ``k`` (after ``last_k``) on ``channel``'s ``rows`` ``H``, whose stored
        gain is ``K``, and ``U`` after it (module docstring): ``K`` itself when there is no deviation
        or it retires against the diagonal ``S_diag()`` of the stored prior, else the filter's gain
        ``K*`` of the prior ``S + V V'``."""
        if k > last_k + 1:
            self.gaps += 1
            self.missed += k - last_k - 1
        V = self.prior(last_k, k)
        self._memo = None
        self._since += 1
        if V is not None and self._since % RETIRE_EVERY == 0 and self.retires(V, S_diag()):
            self.retired += 1
            V = None
        if V is None:
            self.U = None
            self._since = 0
            return K
        W, Ws, cols = self._innovation(k, channel, rows)
        HV = H[:, cols] @ V[cols]
        Kx = np.linalg.solve(W + HV @ HV.T, (K @ W + V @ HV.T).T).T
        r = V.shape[1]
        U = np.empty((V.shape[0], r + Ws.shape[0]))
        np.subtract(V, Kx @ HV, out=U[:, :r])
        np.matmul(Kx - K, Ws, out=U[:, r:])
        if U.shape[1] >= 2 * U.shape[0]:
            U = np.linalg.qr(U.T, mode="r").T        # U U' = R' R: n columns
        self.U = U
        return Kx

    def retires(self, V: np.ndarray, S_diag: np.ndarray) -> bool:
        """``||V_i||^2 <= rtol S_ii`` on every row with room for the roundings (module docstring)."""
        v = np.einsum("ij,ij->i", V, V) * (1.0 + 2.0 * (V.shape[1] + 4) * _EPS)
        return bool(np.all(v <= self.rtol * np.abs(S_diag) * (1.0 - 4.0 * _EPS)))


def _seen(H: np.ndarray) -> np.ndarray:
    """The states rows ``H`` read (the columns holding a nonzero)."""
    return np.flatnonzero(np.any(H != 0, axis=0))
