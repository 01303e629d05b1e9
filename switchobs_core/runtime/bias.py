"""A persistent bias on a channel: two one-sided CUSUMs per output row on normalised innovations.

A sample of channel ``c`` gives the innovation ``nu = y - C_r x_hat^-`` (the prior) with, when the
noise model holds, zero mean and the covariance ``S = C_r P^- C_r' + R`` (:mod:`switchobs_core.runtime.gate`).
Each row ``j`` is normalised, ``s_j = nu_j / sqrt(S_jj)`` (at least ``v_max / 3`` with a declared
bound, read as three standard deviations, so a noise model tighter than the declared noise does
not alarm on the noise itself; the covariance is needed: :class:`~switchobs_core.runtime.recovery.Recovery`
runs no CUSUM without one), and fed to Page's CUSUM
in both directions,

.. math::

    g^+_k = \\max(0, g^+_{k-1} + s_k - k_{ref}), \\qquad g^-_k = \\max(0, g^-_{k-1} - s_k - k_{ref}),

kept per channel and row (the rows a channel shares with another, e.g. the camera's, have one
statistic per channel). An alarm is ``g > h``. Stated delay (Siegmund's approximation, a bias of
``b`` standard deviations that the filter does not absorb in the meantime):

.. math::

    \\text{delay} \\approx \\frac{h + 1.166}{b - k_{ref}} \\text{ samples of that channel,}

with the defaults ``k_ref = 1``, ``h = 8``: 2.3 samples for ``b = 5``, 3.1 for ``b = 4``, 4.6 for ``b = 3``
(at 50 Hz and a channel active 60 % of the time, about 0.08, 0.10, 0.15 s). The false-alarm rate
per row and direction under Gaussian noise of the modelled covariance is about
``2 k_ref^2 / (e^{2 k_ref (h + 1.166)} - 2 k_ref (h + 1.166) - 1)`` per sample: 2e-8 with the
defaults. A statistical test, like the chi-square gate: it guarantees nothing; a bias within the
declared ``noise_max`` is noise the bounds already allow, and the test's purpose is to withdraw
them when a larger one (which they do not allow) persists. After an alarm the statistics restart,
so the end of a bias (the innovations jump back) alarms too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["BiasAlarm", "BiasDetector", "cusum_delay", "unit_normalised"]

#: The defaults: reference value (standard deviations) and threshold.
K_REF = 1.0
H = 8.0


def cusum_delay(b: float, k_ref: float = K_REF, h: float = H) -> float:
    """Siegmund's approximation of the CUSUM's delay (samples) for a bias of ``b`` standard
    deviations (``inf`` for ``b <= k_ref``)."""
    return (h + 1.166) / (b - k_ref) if b > k_ref else math.inf


def unit_normalised(nu: np.ndarray, P: np.ndarray, r_diag: list[float], v_max: float | None) -> list[float] | None:
    """The normalised innovations ``s_j = nu_j / sd_j``, ``sd_j = sqrt(max(P_jj + R_jj, 0))`` (at least
    ``v_max / 3`` with a declared bound), for rows that each select one state (``C_r P C_r' = P``, ``P``
    finite): the diagonal of ``S = P + R`` as the arrays compute it, one IEEE operation per entry in
    Python floats. None when a spread is 0 (``s`` is then not finite: :meth:`BiasDetector.update`
    ignores the sample)."""
    third = None if v_max is None else v_max / 3.0
    out = []
    for nj, pj, rj in zip(nu.tolist(), P.diagonal().tolist(), r_diag, strict=True):
        d = pj + rj
        sd = math.sqrt(0.0 if 0.0 > d else d)       # np.maximum(d, 0): a NaN stays
        if third is not None and third > sd:        # np.maximum(sd, third): a NaN stays
            sd = third
        if sd == 0.0:
            return None
        out.append(nj / sd)
    return out


@dataclass(frozen=True)
class BiasAlarm:
    """A CUSUM alarm: ``channel``, output ``row`` (0-based, of the channel's ``C``), ``sign`` (+1: the
    measurement reads high), the statistic and the threshold."""

    channel: int
    row: int
    sign: int
    g: float
    h: float

    def describe(self, label: str = "") -> str:
        """One line for logs and diagnostics."""
        what = label or f"row {self.row}"
        return (f"a persistent bias on channel {self.channel}, {what} (reads {'high' if self.sign > 0 else 'low'}; "
                f"CUSUM {self.g:.3g} > {self.h:g}): the noise is beyond the declared noise_max")


class BiasDetector:
    """The CUSUMs of the module docstring for channels with ``p`` rows each.

    ``d = BiasDetector(p, k_ref, h)``; ``d.update(channel, rows, s)`` with the normalised
    innovations ``s`` of the rows ``rows`` (0-based, None: all) returns a :class:`BiasAlarm` or None;
    ``d.reset()`` clears every statistic.
    """

    def __init__(self, p: tuple[int, ...], k_ref: float = K_REF, h: float = H) -> None:
        self.p = tuple(int(q) for q in p)
        self.k_ref = float(k_ref)
        self.h = float(h)
        self.alarms = 0
        self.reset()

    def reset(self) -> None:
        """Every statistic back to 0."""
        self._gp = [[0.0] * q for q in self.p]
        self._gn = [[0.0] * q for q in self.p]

    @property
    def g_pos(self) -> list[np.ndarray]:
        """The statistics ``g^+`` per channel (copies)."""
        return [np.array(g) for g in self._gp]

    @property
    def g_neg(self) -> list[np.ndarray]:
        """The statistics ``g^-`` per channel (copies)."""
        return [np.array(g) for g in self._gn]

    def update(self, channel: int, rows: np.ndarray | list[int] | None,
               s: np.ndarray | list[float]) -> BiasAlarm | None:
        """One sample's normalised innovations (one per row); an alarm restarts that channel's statistics.
        The statistics are Python floats: the same IEEE operations as the arrays' (``g + s - k_ref``, then
        the larger of it and 0), without a numpy call per sample."""
        i = channel - 1
        if type(s) is list and all(type(sj) is float for sj in s):     # unit_normalised's: taken as it is
            v = s
        else:
            v = s.tolist() if isinstance(s, np.ndarray) and s.dtype == np.float64 else \
                np.asarray(s, dtype=float).tolist()
        gp, gn = self._gp[i], self._gn[i]
        idx = range(len(gp)) if rows is None else rows
        if isinstance(v, float):        # one value for every row
            v = [v] * len(idx)
        if len(v) != len(idx):
            raise ValueError(f"{len(v)} normalised innovations for {len(idx)} rows of channel {channel}")
        for sj in v:
            if sj - sj != 0.0:      # inf or NaN
                return None
        k = self.k_ref
        for j, sj in zip(idx, v):       # finite steps: g is never NaN (an infinite g alarms and restarts)
            a = gp[j] + sj - k
            gp[j] = a if a > 0.0 else 0.0
            a = gn[j] - sj - k
            gn[j] = a if a > 0.0 else 0.0
        mp, mn = max(gp), max(gn)
        if mp <= self.h and mn <= self.h:
            return None
        sign, j, g = (1, gp.index(mp), mp) if mp >= mn else (-1, gn.index(mn), mn)
        self.alarms += 1
        gp[:] = [0.0] * len(gp)
        gn[:] = [0.0] * len(gn)
        return BiasAlarm(channel, j, sign, g, self.h)
