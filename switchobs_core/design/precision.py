"""Whether a design fits in double precision, and the refusal when it does not (beyond the paper).

A double resolves 16 significant digits (unit roundoff ``u = 2^-53 = 1.1e-16``). Every matrix a
design forms carries, from each operation, an absolute rounding error of about ``u`` times its
norm; a quantity that spans a dynamic range ``D`` (its largest scale over its smallest) keeps about
``log10(1 / (u D))`` correct digits at its smallest scale. One limit serves both gain families:
:data:`PRECISION_RANGE` ``= 1e12``, where ``u D = 1.1e-4`` leaves four digits; at ``1 / u = 9e15``
none is left.

Kalman design (:mod:`switchobs_core.design.kalman`). What must be resolved is the periodic
covariance: its best-known directions (after a view, at the level of the measurement noise) are
what ``S = H P H' + R`` and the gain ``K = P H' S^{-1}`` are made of in the measured rows, and
the rounding made where it is largest (just before a channel unseen for long is viewed again)
is carried to the phases where it is smallest. Its span over the period,

.. math::

    D = \\frac{\\max_k \\lambda_{\\max}(P^-_k)}{\\min_k \\lambda_{\\min}(P^-_k)},

taken in the balanced coordinates of ``(A, C)`` (:func:`state_scale`; the rigorous bound's, which
take out most of a badly scaled state's units),
must stay within :data:`PRECISION_RANGE` (:func:`check_covariance`). The camera model with 32
agents whose modes reach 1/s, every residence 1 s, needs ``D`` about 1e29: its table's
covariance form lost positive definiteness after 21 s at run time (``S`` with an eigenvalue
of -3.3e-6).

LMI design (:mod:`switchobs_core.design.lmi`). What must be resolved is the error map of a
cycle (the product of the steps' maps, e:xtilde_dyn_piecewise), a contraction whose product
passes through the growth ``g`` of the unseen directions: its entries carry ``u g`` relative to
the contraction, so ``g`` must stay within :data:`PRECISION_RANGE`.

Before the design (cheap, and where the design itself would overflow):
:func:`check_unseen`. The directions only channel ``rho`` sees, ``V_rho`` (the unobservable
subspace of the other channels' stacked outputs, invariant under ``A``), are not corrected by
any other channel's sample or gain (``H v = 0`` there): while ``rho`` is unseen for ``T``
seconds, their error evolves open loop and grows by

.. math::

    g_\\rho = \\| e^{A T}|_{V_\\rho} \\|_2 .

For the Kalman design this bounds the span from below, ``D >= g_rho^2``: with ``M`` the
closed-loop map from the prior of the first sample after a view of ``rho`` to the prior of its
next view (``T`` apart; ``M = e^{A T}`` on ``V_rho``), ``P^-_b >= M P^-_a M'`` (every correction
and prediction only adds a positive semidefinite term), and for a unit ``v`` in ``V_rho`` with
``|M v| = g`` and ``w = M v / g``: ``w' P^-_b w >= lambda_min(P^-_a) |M' w|^2 >= lambda_min(P^-_a) g^2``.
So ``g_rho^2 > PRECISION_RANGE`` is refused before the doubling (the design would be refused
after it anyway), and for the LMI design ``g_rho > PRECISION_RANGE`` before its SDPs (the cycle
map passes through ``g_rho``).

What fixes it: shorter unseen stretches (shorter residences of the other channels, a faster
cycle) or slower modes. A refusal names the longest stretch that fits, ``T`` with
``g(T)^power = PRECISION_RANGE`` (bisection; ``power`` 2 for a covariance, 1 for an error map).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..exceptions import PrecisionError
from ..model.decomposition import unobservable_subspace
from ..numerics.scaling import balance, balanced

__all__ = [
    "PRECISION_RANGE",
    "Unseen",
    "CovarianceSpan",
    "exclusive_subspaces",
    "pattern_stretches",
    "cycle_stretches",
    "unseen_growth",
    "beyond_precision",
    "check_unseen",
    "covariance_span",
    "check_covariance",
    "cycles_label",
]

#: Largest dynamic range a design may ask double precision to carry (module docstring): four digits left.
PRECISION_RANGE = 1e12
_LIMIT_TEXT = "at most 1e12 fits in the 16 digits of a double with 4 left"
#: Systems whose exclusive subspaces are kept (by fingerprint).
_CACHE: dict[str, tuple] = {}
_CACHE_MAX = 8


@dataclass(frozen=True)
class Unseen:
    """The longest stretch a channel goes unseen and what its exclusive directions grow by meanwhile.

    Attributes
    ----------
    channel : int
        1-based channel.
    name : str
        Its name.
    seconds : float
        The longest stretch without a sample of the channel (inf: never seen).
    growth : float
        ``g = ||e^{A T}|_V||_2`` over that stretch on the directions only this channel sees (1 when
        there are none).
    """

    channel: int
    name: str
    seconds: float
    growth: float


@dataclass(frozen=True)
class CovarianceSpan:
    """The span of a set of covariances: ``largest`` (at ``k_largest``, mostly along ``along_largest``)
    over ``smallest`` (at ``k_smallest``, along ``along_smallest``)."""

    span: float
    largest: float
    k_largest: int
    along_largest: str
    smallest: float
    k_smallest: int
    along_smallest: str


def exclusive_subspaces(system: Any) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per channel ``rho``: ``(V, A_V)``, an orthonormal basis of the directions only ``rho`` sees (the
    unobservable subspace of the other channels' stacked outputs) and ``A`` on it, ``V' A V``
    (module docstring); kept per system fingerprint."""
    key = system.fingerprint()
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    d = state_scale(system)
    A = balanced(np.asarray(system.A, dtype=float), d)
    C = [np.asarray(Ci, dtype=float) * d[None, :] for Ci in system.C]
    out = []
    for rho in range(len(C)):
        others = [Ci for j, Ci in enumerate(C) if j != rho]
        V = unobservable_subspace(A, np.vstack(others)) if others else np.eye(A.shape[0])
        out.append((V, V.T @ A @ V))
    if len(_CACHE) >= _CACHE_MAX:
        _CACHE.clear()
    res = _CACHE[key] = tuple(out)
    return res


def pattern_stretches(channels: Sequence[int], blind: Sequence[bool], rate: float, N: int) -> tuple[float, ...]:
    """Per channel, the longest stretch (s) of a periodic sample pattern from the first sample after a
    view of the channel to its next view (blind samples are no views; inf: never viewed)."""
    K = len(channels)
    views: list[list[int]] = [[] for _ in range(N)]
    for k, c in enumerate(channels):
        if not (blind and blind[k]):
            views[int(c) - 1].append(k)
    out = []
    for v in views:
        if not v:
            out.append(math.inf)
            continue
        gap = max((v[(i + 1) % len(v)] - v[i]) % K or K for i in range(len(v)))
        out.append((gap - 1) / rate)
    return tuple(out)


def cycle_stretches(h: Sequence[float], dead_time: float = 0.0) -> tuple[float, ...]:
    """Per channel, the time a cycle of residences ``h`` leaves it unseen: the others' residences and
    the dead time at the start of its own (continuous outputs, the LMI design)."""
    tau = float(sum(h))
    return tuple(tau - float(hi) + float(dead_time) for hi in h)


def cycles_label(cycles: Sequence[Any]) -> str:
    """The cycles of a design in a message: ``Cycle.label()``, or ``h = 1 s on all 32 channels``."""
    out = []
    for c in cycles:
        h = tuple(c.h)
        if len(h) > 2 and len(set(h)) == 1:
            dead = f", dead {c.dead_time:g} s" if c.dead_time else ""
            out.append(f"h = {h[0]:g} s on all {len(h)} channels{dead}")
        else:
            out.append(c.label())
    return "cycle " + "; ".join(out) if len(out) == 1 else "cycles " + "; ".join(out)


def state_scale(system: Any) -> np.ndarray:
    """The balancing ``d`` of ``(A, C)`` (powers of two, :func:`~switchobs_core.numerics.scaling.balance`):
    spans and growths are measured in the coordinates ``D^-1 x``, the rigorous bound's. The balancing
    takes out most of a badly scaled state's units, not all: it is not equivariant under a diagonal
    change of units (the paper model's span, 2.7e4, reads 1.7e9 with its states rescaled by
    2^-6..2^9)."""
    return balance(np.asarray(system.A, dtype=float), np.vstack([np.asarray(Ci, dtype=float) for Ci in system.C]))


def _growth(AV: np.ndarray, T: float) -> float:
    if AV.size == 0 or T <= 0:
        return 1.0
    if not math.isfinite(T):
        return math.inf
    with np.errstate(over="ignore", invalid="ignore"):
        g = float(np.linalg.norm(expm(AV * T), 2))
    return g if math.isfinite(g) else math.inf


def unseen_growth(system: Any, stretches: Sequence[float]) -> list[Unseen]:
    """:class:`Unseen` of every channel for the given stretches (s), one per channel."""
    names = getattr(system, "channel_names", ()) or tuple(f"channel{i + 1}" for i in range(system.N))
    return [Unseen(i + 1, names[i], float(T), _growth(AV, float(T)))
            for i, ((_, AV), T) in enumerate(zip(exclusive_subspaces(system), stretches))]


def _fits(system: Any, u: Unseen, power: int, limit: float = PRECISION_RANGE) -> float:
    """The longest stretch (s) over which the channel's growth ``g`` keeps ``g^power`` within ``limit``."""
    AV = exclusive_subspaces(system)[u.channel - 1][1]
    lo, hi = 0.0, u.seconds if math.isfinite(u.seconds) else 1e6
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _growth(AV, mid) ** power <= limit:
            lo = mid
        else:
            hi = mid
    return lo


def beyond_precision(system: Any, stretches: Sequence[float], *, power: int, what: str) -> str:
    """The refusal (one line) when some channel's growth over its unseen stretch, to ``power`` (2: a
    covariance, 1: an error map), exceeds :data:`PRECISION_RANGE`; "" when every channel fits."""
    unseen = [u for u in unseen_growth(system, stretches) if math.isfinite(u.seconds)]
    over = [u for u in unseen if not u.growth ** power <= PRECISION_RANGE]
    if not over:
        return ""
    w = max(over, key=lambda u: u.growth)
    need = w.growth ** power
    fit = min(_fits(system, u, power) for u in over)
    quantity = "the periodic covariance must span" if power == 2 else "the error map of a cycle passes through"
    others = f" ({len(over) - 1} other channel(s) too)" if len(over) > 1 else ""
    N = int(system.N)
    equal = f" (equal residences of at most {fit / (N - 1):.3g} s)" if N > 1 else ""
    grows = f"{w.growth:.3g}-fold" if math.isfinite(w.growth) else "past the largest double"
    return (f"{what} is beyond double precision: channel {w.channel} ({w.name}) goes unseen for {w.seconds:.4g} s and "
            f"the error of the directions only it sees grows {grows} meanwhile{others}, so {quantity} at least "
            f"{need:.3g} ({_LIMIT_TEXT}); shorten the residences or the cycle so that no channel goes unseen "
            f"for more than {fit:.3g} s{equal}, or slow its modes")


def check_unseen(system: Any, stretches: Sequence[float], *, power: int, what: str) -> None:
    """Raise :class:`~switchobs_core.exceptions.PrecisionError` with :func:`beyond_precision`'s line
    when the design cannot fit (module docstring)."""
    msg = beyond_precision(system, stretches, power=power, what=what)
    if msg:
        raise PrecisionError(msg)


def _along(system: Any, v: np.ndarray) -> str:
    labels = getattr(system, "state_labels", None) or tuple(f"x{i}" for i in range(v.size))
    return str(labels[int(np.argmax(np.abs(v)))])


def covariance_span(system: Any, covariances: Sequence[np.ndarray]) -> CovarianceSpan:
    """The span ``max_k lambda_max / min_k lambda_min`` of ``covariances`` in the balanced coordinates
    of :func:`state_scale` (module docstring), with where its ends lie (inf when a covariance is
    singular or not finite)."""
    lo, hi, klo, khi = math.inf, 0.0, 0, 0
    d = state_scale(system)
    covariances = [np.asarray(P, dtype=float) / np.outer(d, d) for P in covariances]
    for k, P in enumerate(covariances):
        if not np.all(np.isfinite(P)):
            return CovarianceSpan(math.inf, math.inf, k, "", lo, klo, "")
        w = np.linalg.eigvalsh(P)
        if w[-1] > hi:
            hi, khi = float(w[-1]), k
        if w[0] < lo:
            lo, klo = float(w[0]), k
    vhi = np.linalg.eigh(covariances[khi])[1][:, -1]
    vlo = np.linalg.eigh(covariances[klo])[1][:, 0]
    span = hi / lo if lo > 0 else math.inf
    return CovarianceSpan(span, hi, khi, _along(system, vhi), lo, klo, _along(system, vlo))


def check_covariance(system: Any, covariances: Sequence[np.ndarray], stretches: Sequence[float], *,
                     what: str) -> CovarianceSpan:
    """The span of the period's priors (:func:`covariance_span`); raise
    :class:`~switchobs_core.exceptions.PrecisionError` when it exceeds :data:`PRECISION_RANGE`,
    naming its ends and the longest unseen stretch."""
    s = covariance_span(system, covariances)
    if s.span <= PRECISION_RANGE:
        return s
    unseen = [u for u in unseen_growth(system, stretches) if math.isfinite(u.seconds)]
    hint = ""
    if unseen:
        # the channel whose directions grow most; the stretch that would fit, if the span scales with its g^2
        w = max(unseen, key=lambda u: u.growth)
        fit = _fits(system, w, 2, PRECISION_RANGE * w.growth ** 2 / s.span) if w.growth > 1 else 0.0
        hint = (f" (channel {w.channel} ({w.name}), whose directions grow most, goes unseen for {w.seconds:.4g} s"
                + (f"; about {fit:.3g} s would fit" if fit > 0 else "") + ")")
    raise PrecisionError(
        f"{what} is beyond double precision: its periodic covariance spans {s.span:.3g} (variance {s.largest:.3g} "
        f"along {s.along_largest} at sample {s.k_largest}, {s.smallest:.3g} along {s.along_smallest} at sample "
        f"{s.k_smallest}; {_LIMIT_TEXT}); shorten the residences or the cycle{hint}, or slow the modes that grow "
        "while a channel is unseen")
