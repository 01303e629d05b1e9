"""The innovation consistency test: a sample that the published bound cannot explain.

A sample of channel ``c`` holding the output rows ``r`` at time ``t`` is
``y = C_r x(t) + v`` with ``C_r`` those rows of ``C_c`` (e:system) and ``v`` the
measurement noise. Before the sample is used, the observer's prior estimate ``x_hat(t)`` has
the error ``e = x(t) - x_hat(t)``, and the observer keeps a rigorous bound ``||e|| <= b(t)``:
the exact bound (noise-free samples) or, with a declared ``|v_j| <= v_max``, the noise bound
(:mod:`switchobs_core.numerics.rounding`; both include floating-point rounding). So the innovation obeys

.. math::

    \\|\\nu\\| = \\|y - C_r \\hat x(t)\\| = \\|C_r e + v\\| \\le \\|C_r\\|_2 \\, b(t) + \\sqrt{p} \\, v_{max}

with ``p = len(r)``; where the observer keeps the ellipsoid ``S`` that the bound is the largest
axis of, ``||C_r||_2 b(t)`` is replaced by the tighter ``sqrt(lambda_max(C_r S C_r'))``
(:func:`projected_bound`). The computed innovation differs from ``nu`` by the rounding of
``C_r x_hat`` and of the subtraction, at most ``gamma(n + 1) (||C_r||_F ||x_hat|| + ||y||)``
(Higham, Accuracy and Stability of Numerical Algorithms, eq. 3.11); the test adds that
allowance, and takes ``||C_r||_2`` from the SVD enlarged by :data:`NORM_SLACK` (the SVD's
relative error is a few ``n u``), so a model that holds never fails it.

A sample that fails it is therefore a *proof* that the model is broken for that sample: the
sample was attributed to the wrong channel, is in the wrong frame, comes from a faulty sensor,
or the bodies do not move as ``A`` says (a manoeuvre beyond the declared disturbance, a
collision), or the noise exceeds the declared bound (:func:`likely_causes` orders these by the
evidence for a diagnostic). Nothing can then be guaranteed about the estimate: the callers withdraw every
bound they publish. When the sample is consistent with exactly one other channel, that channel
is the only one the model allows, and the sample can be re-attributed to it
(:func:`consistent_channels`). :class:`InnovationTest` runs the test for a system's channels
against the observer's prior (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior`).

The test is a necessary condition only: a broken model whose innovations stay inside the
allowance goes unnoticed (the bound is then still an honest statement about everything the data
has shown). It is as sharp as the bound: with ``b(t)`` at the rounding floor (noise-free samples
after convergence) an error of 1e-9 of ``||x||`` is caught; right after start-up, with
``b = e0``, only gross errors are.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..numerics.frobenius import underflow_slack
from ..numerics.rounding import UNIT_ROUNDOFF, PendingSet, assembled, gamma, largest_eigenvalue

__all__ = ["NORM_SLACK", "Consistency", "InnovationTest", "block_product", "check_innovation", "consistent_channels",
           "innovation_allowance", "is_unit", "likely_causes", "output_rows", "projected_bound", "rows_product",
           "seen_columns", "spectral_norm", "squared_norm"]

#: Relative slack on the allowance, for the rounding of the allowance's own arithmetic (a few
#: products and sums of non-negative numbers: far below 1e-12 relative).
_SLACK = 1e-12
#: Relative enlargement of the computed spectral norm ``||C_r||_2`` (LAPACK's SVD is accurate to
#: a small multiple of ``n u`` relative; 1e-10 covers n up to about 1e5).
NORM_SLACK = 1e-10


def spectral_norm(C_rows: np.ndarray) -> float:
    """An upper bound on ``||C_rows||_2``: the SVD's largest singular value times ``1 + NORM_SLACK``."""
    if C_rows.size == 0:
        return 0.0
    return float(np.linalg.norm(C_rows, 2)) * (1.0 + NORM_SLACK)


@dataclass(frozen=True, init=False)
class Consistency:
    """The outcome of the test for one sample and one channel.

    ``innovation`` is ``||y - C_r x_hat(t)||`` as computed; ``allowance`` the largest value a
    model that holds allows (module docstring; on an ellipsoid, when the sample passes, it may be a smaller
    allowance the innovation is already within: :func:`innovation_allowance`'s ``within``); ``bound`` the
    error bound ``b(t)`` used.
    """

    channel: int
    innovation: float
    allowance: float
    bound: float          # the error bound's largest axis (nan when the test passed on an ellipsoid)
    #: The innovation ``y - C_r x_hat`` the test computed (the bias test's, :meth:`Recovery.before
    #: <switchobs_core.runtime.recovery.Recovery.before>`, shares it).
    nu: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __init__(self, channel: int, innovation: float, allowance: float, bound: float,
                 nu: np.ndarray | None = None) -> None:
        # the fields into the instance's dict (frozen: no __setattr__), as Envelope's: one test a sample
        d = self.__dict__
        d["channel"], d["innovation"], d["allowance"], d["bound"], d["nu"] = channel, innovation, allowance, bound, nu

    @property
    def ok(self) -> bool:
        """True when the sample is consistent with the model (``innovation <= allowance``)."""
        return self.innovation <= self.allowance

    @property
    def ratio(self) -> float:
        """``innovation / allowance`` (> 1: inconsistent)."""
        return self.innovation / self.allowance if self.allowance > 0 else math.inf

    def describe(self) -> str:
        """One line for logs and diagnostics."""
        return (f"channel {self.channel}: innovation {self.innovation:.3g} > {self.allowance:.3g} allowed by the "
                f"bound {self.bound:.3g} ({self.ratio:.3g}x)" if not self.ok else
                f"channel {self.channel}: innovation {self.innovation:.3g} <= {self.allowance:.3g}")


def seen_columns(C_rows: np.ndarray) -> np.ndarray | None:
    """The columns of ``C_rows`` that hold a nonzero (a sample sees a few states), or None when
    they are more than a quarter of them (then the dense product is the faster)."""
    c = np.flatnonzero(np.any(C_rows != 0.0, axis=0))
    return c if 4 * c.size <= C_rows.shape[1] else None


def is_unit(Cc: np.ndarray) -> bool:
    """Whether ``Cc`` (``C_r`` on its :func:`seen_columns`) is the identity: rows that each select one
    seen state, in the columns' order (a camera's position rows)."""
    return Cc.ndim == 2 and Cc.shape[0] == Cc.shape[1] and bool(np.array_equal(Cc, np.eye(Cc.shape[0])))


def block_product(Cc: np.ndarray, B: np.ndarray, unit: bool = False) -> np.ndarray:
    """``Cc B Cc'`` for a block ``B`` on the seen columns; ``unit`` (:func:`is_unit` of ``Cc``) and ``B``
    finite: ``B`` itself (not a copy: read-only), the numbers of the product (each of its entries is
    one entry of ``B`` times 1 plus exact zeros; a zero's sign aside), without the two products."""
    if unit and np.isfinite(B).all():
        return B
    return Cc @ B @ Cc.T


def rows_product(C_rows: np.ndarray, S: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
    """``C_r S C_r'``, over the columns ``cols`` of :func:`seen_columns` only when given: the
    terms of the other columns are exact zeros, so the sums are shorter (and for rows that each
    select one state, as a camera's position, the result is exact either way)."""
    if cols is None:
        return C_rows @ S @ C_rows.T
    Cc = C_rows[:, cols]
    return Cc @ S[cols[:, None], cols] @ Cc.T      # the block S[np.ix_(cols, cols)]


def projected_bound(C_rows: np.ndarray, S: np.ndarray, cols: np.ndarray | None = None,
                    fC2: float | None = None, unit: bool = False, Cc: np.ndarray | None = None) -> float:
    """A rigorous bound on ``||C_r e||`` over the ellipsoid ``e in {S^(1/2) u : ||u|| <= 1}``:
    ``sqrt(lambda_max(C_r S C_r'))`` (``p x p``, cheap), inflated for the rounding of the
    product (``gamma(2n + 2) ||C_r||_F^2 trace S``, as :mod:`switchobs_core.numerics.rounding` step 6) and
    of the eigenvalue solver (relative ``2 p u``). Tighter than ``||C_r||_2 sqrt(lambda_max(S))``
    when the error's set is long in directions the rows do not see. ``cols``: :func:`seen_columns`
    of ``C_r`` (the product over them, :func:`rows_product`; the allowance is the dense one's);
    ``fC2``: :func:`squared_norm` of ``C_r`` when the caller keeps it. ``S`` may be a
    :class:`~switchobs_core.numerics.rounding.PendingSet`: its block and trace are read without
    assembling it (the same doubles). ``unit``: :func:`is_unit` of ``C_r`` on ``cols`` (the block is
    then read as it is, :func:`block_product`); ``Cc``: ``C_r[:, cols]`` when the caller keeps it."""
    p, n = C_rows.shape
    if p == 0:
        return 0.0
    P, tr, fP = _projected_block(C_rows, S, cols, unit, Cc)
    fC2 = squared_norm(C_rows) if fC2 is None else fC2
    return _seen(largest_eigenvalue(P), n, p, fC2, tr, fP)


def _projected_block(C_rows: np.ndarray, S: Any, cols: np.ndarray | None, unit: bool,
                     Cc: np.ndarray | None) -> tuple[np.ndarray, float, float]:
    """:func:`projected_bound`'s ``(P, trace S, ||P||_F)`` (``p >= 1`` rows), ``P`` the symmetric part of
    ``C_r S C_r'`` and its norm as computed."""
    B = None
    if isinstance(S, PendingSet) and cols is not None:
        B, tr = S.block(cols), S.trace
        if Cc is None:
            Cc = C_rows[:, cols]
        P = B if unit else block_product(Cc, B)     # unit: B's finiteness is read off fP below
    else:
        S = assembled(S)
        P, tr = rows_product(C_rows, S, cols), float(np.trace(S))
    P = 0.5 * (P + P.T)
    fP = math.sqrt(float((P * P).sum()))       # np.sum's reduction, without its wrapper
    if unit and B is not None and not math.isfinite(fP):
        # a finite fP has every entry of P = (B + B') / 2 finite, so B's: block_product(Cc, B, True) is B
        # itself, as taken above; else it decides (B finite: the same P; not: the product)
        P = block_product(Cc, B, unit)
        P = 0.5 * (P + P.T)
        fP = math.sqrt(float((P * P).sum()))
    return P, tr, fP


def _seen(lam: float, n: int, p: int, fC2: float, tr: float, fP: float) -> float:
    """:func:`projected_bound` from the block's computed largest eigenvalue ``lam`` (or a value below it)."""
    lam = max(lam, 0.0) + gamma(2 * n + 2) * fC2 * abs(tr) + 2 * p * UNIT_ROUNDOFF * fP
    return math.sqrt(lam) * (1.0 + _SLACK)


def squared_norm(C_rows: np.ndarray) -> float:
    """``||C_r||_F^2`` as the allowances compute it (the sum of the squared entries)."""
    return float(np.sum(C_rows * C_rows))


def innovation_allowance(C_rows: np.ndarray, bound: float | np.ndarray, v_max: float, x_hat: np.ndarray,
                         y: np.ndarray, norm_C: float | None = None, cols: np.ndarray | None = None,
                         fC2: float | None = None, unit: bool = False, Cc: np.ndarray | None = None,
                         within: float | None = None) -> float:
    """The largest computed innovation ``||y - C_r x_hat||`` a model that holds allows (with ``within``, a
    smaller allowance may be returned, below).

    Parameters
    ----------
    C_rows : (p, n) ndarray
        The rows of ``C_c`` the sample holds.
    bound : float, (n, n) ndarray or PendingSet
        Rigorous bound ``b(t) >= ||x(t) - x_hat(t)||`` on the prior error (rounding included), or
        the shape matrix ``S`` of an ellipsoid holding it (:func:`projected_bound`, tighter).
    v_max : float
        Declared bound on every noise entry, ``|v_j| <= v_max`` (0 for noise-free samples).
    x_hat, y : ndarray
        The prior estimate and the sample (for the rounding allowance).
    norm_C : float, optional
        :func:`spectral_norm` of ``C_rows`` when the caller keeps it (computed if None).
    cols : ndarray, optional
        :func:`seen_columns` of ``C_rows`` when the caller keeps them (:func:`projected_bound`).
    fC2 : float, optional
        :func:`squared_norm` of ``C_rows`` when the caller keeps it.
    unit : bool
        :func:`is_unit` of ``C_rows`` on ``cols`` when the caller keeps it (:func:`projected_bound`).
    Cc : ndarray, optional
        ``C_rows[:, cols]`` when the caller keeps it (:func:`projected_bound`).
    within : float, optional
        A computed innovation (the test's): on an ellipsoid, when it is within the allowance with the
        block's largest diagonal entry ``d`` less ``4 p u (||P||_F + p sqrt(eta))`` (the norm as computed
        plus what underflow hides from it) in place of its computed largest eigenvalue, that allowance
        is returned and the eigenvalue problem is not solved. It is at most the full one:
        ``lambda_max(P) >= d``, and the solver's eigenvalue is within ``2 p u ||P||_F`` of
        ``lambda_max`` (the model :func:`projected_bound` allows for); so the test's outcome is the full
        allowance's.
    """
    p, n = C_rows.shape
    fC2 = squared_norm(C_rows) if fC2 is None else fC2
    fC = math.sqrt(fC2)
    n2 = spectral_norm(C_rows) if norm_C is None else norm_C
    xn = math.sqrt(float(x_hat @ x_hat))
    yn = math.sqrt(float(y @ y))
    noise, rounding = math.sqrt(p) * v_max, gamma(n + 1) * (fC * xn + yn)
    if not isinstance(bound, (np.ndarray, PendingSet)):
        seen = n2 * bound
    elif within is None or p == 0:
        seen = projected_bound(C_rows, bound, cols, fC2, unit, Cc)
    else:
        P, tr, fP = _projected_block(C_rows, bound, cols, unit, Cc)
        if math.isfinite(fP):       # every entry of P finite
            # fP with what underflow hides from it (p sqrt(eta)): LAPACK scales a block whose squares
            # underflow, and its eigenvalue may then fall below the largest diagonal entry
            low = _seen(max(P.diagonal().tolist()) - 4.0 * p * UNIT_ROUNDOFF * (fP + underflow_slack(p * p)),
                        n, p, fC2, tr, fP)
            low = (low + noise + rounding) * (1.0 + _SLACK)
            if within <= low:
                return low
        seen = _seen(largest_eigenvalue(P), n, p, fC2, tr, fP)
    return (seen + noise + rounding) * (1.0 + _SLACK)


def check_innovation(C_rows: np.ndarray, channel: int, bound: float, v_max: float, x_hat: np.ndarray,
                     y: np.ndarray, norm_C: float | None = None, cols: np.ndarray | None = None,
                     fC2: float | None = None, unit: bool = False, Cc: np.ndarray | None = None) -> Consistency:
    """The test for one sample ``y`` of ``channel`` (rows ``C_rows``) against the prior ``x_hat``
    (the optional arguments: :func:`innovation_allowance`'s)."""
    nu = y - C_rows @ x_hat
    inn = math.sqrt(float(nu @ nu))
    allow = innovation_allowance(C_rows, bound, v_max, x_hat, y, norm_C, cols, fC2, unit, Cc, within=inn)
    if isinstance(bound, (np.ndarray, PendingSet)):     # the largest axis, for the report of a failure only
        S = assembled(bound) if inn > allow else None
        b = math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (S + S.T))[-1]), 0.0)) if S is not None else math.nan
    else:
        b = float(bound)
    return Consistency(channel, inn, allow, b, nu)


#: An innovation this many times its allowance points at a gross fault (a wrong channel or frame,
#: a faulty sensor) before a small excess of the declared bounds (a manoeuvre, the noise's tail).
GROSS_RATIO = 10.0


def likely_causes(first: bool, ratio: float, *, e0: float, noise_max: float | None,
                  disturbance_max: float | None) -> str:
    """The assumptions an inconsistent sample breaks, most likely first, as one short line.

    ``first``: the first sample (its prior is ``x_hat(t0)`` with the ball of radius ``e0``: ``e0``
    leads); ``ratio``: innovation / allowance (:attr:`Consistency.ratio`); above
    :data:`GROSS_RATIO` a channel, a bias or a clock fault leads, below it a disturbance or the
    noise beyond what was declared (``noise_max``, ``disturbance_max``: the largest declared
    bounds, None: none)."""
    dist = ("disturbance (a body accelerating beyond disturbance.max = "
            f"{disturbance_max:g})" if disturbance_max else "disturbance (a body off the model: no disturbance.max "
            "declared)")
    noise = f"noise (beyond noise.max = {noise_max:g})" if noise_max is not None else "noise (none declared)"
    gross = ["channel (a wrong channel or frame)", "bias (a sensor offset beyond noise.max)",
             "clock (stamps off the sensor's time)"]
    if first:
        causes = [f"e0 (the initial error ||x_hat(t0) - x(t0)|| exceeds e0 = {e0:g}: raise e0 or give an "
                  "initial_estimate closer to the truth)", gross[0], noise, gross[1]]
    elif ratio >= GROSS_RATIO:
        causes = [*gross, dist, noise]
    else:
        causes = [dist, noise, gross[1], gross[2], gross[0]]
    return "likely causes, most likely first: " + "; ".join(causes)


def consistent_channels(tests: list[Consistency]) -> list[int]:
    """The channels whose test passed, in order."""
    return [t.channel for t in tests if t.ok]


def output_rows(C_c: np.ndarray, rows: Sequence[int] | None) -> np.ndarray:
    """``C_r``: the ``rows`` (0-based; None: all) of a channel's output matrix ``C_c`` that a sample holds."""
    return C_c if rows is None else C_c[list(rows)]


class InnovationTest:
    """The test for the channels of one system, against the observer's prior.

    Parameters
    ----------
    C : sequence of (p_i, n) array_like
        The channels' output matrices ``C_1..C_N`` (e:outputs).
    noise_max : sequence of float, optional
        The declared noise bound per channel (:attr:`SwitchedObserver.noise_max
        <switchobs_core.runtime.observer.SwitchedObserver>`); None: noise-free samples, tested against
        the exact bound.

    ``C_r``, its :func:`spectral_norm`, its :func:`seen_columns`, its :func:`squared_norm`, ``C_r`` on the
    seen columns and :func:`is_unit` of it are kept per ``(channel, rows)``.
    """

    def __init__(self, C: Sequence[np.ndarray], noise_max: Sequence[float] | None = None):
        self.C = tuple(np.asarray(C_i, dtype=float) for C_i in C)
        self.noise_max = None if noise_max is None else tuple(noise_max)
        self._rows: dict[tuple[int, tuple[int, ...] | None], tuple[np.ndarray, float, np.ndarray | None, float,
                                                                   bool, np.ndarray | None]] = {}

    def check(self, prior: tuple, channel: int, rows: Sequence[int] | None, y: np.ndarray) -> Consistency:
        """The test of the sample ``y`` of ``channel`` (``rows`` of its output, 0-based; None:
        all) against ``prior = (x_hat, exact, noise)`` as
        :meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior` gives it at the sample's time:
        the exact bound's set for noise-free samples, the noise bound's with ``noise_max``."""
        x_hat, exact, noise = prior
        key = (channel, None if rows is None else tuple(rows))
        hit = self._rows.get(key)
        if hit is None:
            C_r = output_rows(self.C[channel - 1], rows)
            cols = seen_columns(C_r)
            Cc = None if cols is None else C_r[:, cols]
            hit = self._rows[key] = (C_r, spectral_norm(C_r), cols, squared_norm(C_r),
                                     Cc is not None and is_unit(Cc), Cc)
        C_r, norm_C, cols, fC2, unit, Cc = hit
        if self.noise_max is None:
            return check_innovation(C_r, channel, exact, 0.0, x_hat, y, norm_C, cols, fC2, unit, Cc)
        return check_innovation(C_r, channel, noise, self.noise_max[channel - 1], x_hat, y, norm_C, cols, fC2, unit,
                                Cc)
