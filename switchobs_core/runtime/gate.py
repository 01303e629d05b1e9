"""The chi-square gate: a sample whose normalised innovation the noise model makes improbable.

A sample of channel ``c`` holding the output rows ``r`` is ``y = C_r x + v`` (e:system) with
Gaussian noise ``v`` of covariance ``R``. With ``P^-`` the covariance of the prior error (a
Kalman filter's, or the one the LMI observer propagates), the innovation ``nu = y - C_r x_hat``
has the covariance ``S = C_r P^- C_r' + R``, and its normalised square

.. math::

    \\nu^\\top S^{-1} \\nu \\sim \\chi^2_p, \\qquad p = \\text{len}(r),

when the noise model holds. The gate rejects a sample above the ``1 - alpha`` quantile of that
distribution: a sample of a model that holds is rejected with probability ``alpha`` (the false
alarm rate per sample). The gate is a statistical test and guarantees nothing; the rigorous test
against a published bound is :mod:`switchobs_core.runtime.consistency`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..exceptions import InvalidArgument
from .consistency import output_rows

__all__ = ["ChiSquareGate", "GateResult", "chi2_gate", "nis"]


def nis(C_rows: np.ndarray, P_prior: np.ndarray, R: np.ndarray, x_hat: np.ndarray, y: np.ndarray) -> float:
    """The normalised innovation squared ``nu' S^-1 nu`` with ``S = C_r P^- C_r' + R``.

    With Gaussian noise of covariance ``R``, process noise as modelled, and ``P^-`` the true
    covariance of the prior error, it is chi-square distributed with ``p = len(y)`` degrees of
    freedom.
    """
    # nu = y - C_r x_hat
    nu = y - C_rows @ x_hat
    # S = C_r P^- C_r' + R, symmetrised
    S = C_rows @ P_prior @ C_rows.T + R
    S = 0.5 * (S + S.T)
    return float(nu @ np.linalg.solve(S, nu))


def chi2_gate(p: int, alpha: float) -> float:
    """The threshold ``chi2.ppf(1 - alpha, p)``: a sample of a model that holds exceeds it with
    probability ``alpha`` (the gate's false-alarm rate per sample). ``scipy.special`` is imported here,
    not with this module: an estimator start without the gate (``chi2_alpha`` 0, the default) never pays
    its 10-35 ms (:class:`ChiSquareGate` asks for its thresholds when it is made with ``alpha > 0``)."""
    from scipy.special import chdtri  # the upper-tail inverse of the chi-square distribution
    return float(chdtri(p, alpha))


@dataclass(frozen=True)
class GateResult:
    """The gate's outcome for one sample: its ``nis``, the ``threshold`` for its ``rows`` (the
    degrees of freedom) at the false-alarm rate ``alpha``."""

    channel: int
    nis: float
    threshold: float
    rows: int
    alpha: float

    @property
    def ok(self) -> bool:
        """True when the sample passes (``nis <= threshold``)."""
        return self.nis <= self.threshold

    def describe(self) -> str:
        """One line for logs and diagnostics (of a rejected sample)."""
        return f"NIS {self.nis:.3g} > {self.threshold:.3g} (chi-square, {self.rows} rows, alpha {self.alpha:g})"


class ChiSquareGate:
    """The gate at the false-alarm rate ``alpha`` for the channels of one system.

    Parameters
    ----------
    C : sequence of (p_i, n) array_like
        The channels' output matrices ``C_1..C_N`` (e:outputs).
    alpha : float
        The false-alarm rate per sample, in [0, 1) (0: no gate); else :class:`InvalidArgument` (a rate
        of 1 or more, or NaN, would reject every sample, a negative one turn the gate off silently).

    The thresholds are computed once per number of rows: those of the channels' full outputs when the
    gate is made with ``alpha > 0`` (so the first gated sample does not wait for ``scipy.special``'s
    import), none with ``alpha = 0`` (no gate: ``scipy.special`` is not imported).
    """

    def __init__(self, C: Sequence[np.ndarray], alpha: float):
        self.C = tuple(np.asarray(C_i, dtype=float) for C_i in C)
        self.alpha = float(alpha)
        if not 0.0 <= self.alpha < 1.0:
            raise InvalidArgument(f"the chi-square gate's false-alarm rate alpha must be in [0, 1) (0: no gate); "
                                  f"got {alpha!r}")
        self._thresholds: dict[int, float] = {}
        if self.alpha > 0.0:
            for C_i in self.C:
                self.threshold(C_i.shape[0])

    def threshold(self, p: int) -> float:
        """``chi2.ppf(1 - alpha, p)`` (:func:`chi2_gate`)."""
        if p not in self._thresholds:
            self._thresholds[p] = chi2_gate(p, self.alpha)
        return self._thresholds[p]

    def check(self, channel: int, rows: Sequence[int] | None, y: np.ndarray, x_hat: np.ndarray,
              P_prior: np.ndarray, R: np.ndarray) -> GateResult:
        """The gate for the sample ``y`` of ``channel`` (``rows`` of its output, 0-based; None: all)
        against the prior ``x_hat`` with error covariance ``P_prior``, noise covariance ``R``."""
        C_r = output_rows(self.C[channel - 1], rows)
        p = C_r.shape[0]
        return GateResult(channel, nis(C_r, P_prior, R, x_hat, y), self.threshold(p), p, self.alpha)
