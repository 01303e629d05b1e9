"""The paper's certificate quantities: the cycle factors ``f_ii`` (e:Fk,
e:f11_le_delta_main), **the paper's claim, not a proof** (see :mod:`switchobs_core.certificate`),
and :func:`envelope_ratio`, how far a run exceeds the paper's envelopes (e:z1_evolution).

Equation labels (``e:...``) are those of the paper and resolve in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..bounds.envelope import Segment, envelope_z, error_transitions
from ..exceptions import InvalidArgument
from ..validation import as_finite

__all__ = ["cycle_factor", "paper_factors", "design_dead_time", "EnvelopeRatio", "envelope_ratio"]


def cycle_factor(kappa: float, mu: float, eta: float, active: float, inactive: float) -> float:
    """The paper's cycle factor of one channel (e:Fk, e:f11_le_delta_main).

    ``f = kappa exp(mu (tau - h) - eta h)``: the channel decays at rate ``eta`` for its
    active time ``h`` and grows at most at rate ``mu`` for the rest of the cycle
    ``tau - h``; ``kappa`` is the overshoot of its observer (e:eta1_fixed).

    Parameters
    ----------
    kappa, mu, eta : float
        The channel's overshoot, growth bound and designed decay rate.
    active : float
        ``h``, the time the channel is active in the cycle (s).
    inactive : float
        ``tau - h``, the time it is inactive (s); for a robust design the worst case of
        the box, which need not equal ``tau - h`` of one cycle.

    Returns
    -------
    float
        ``kappa * exp(mu * inactive - eta * active)``; the single place this formula is
        evaluated.

    Raises
    ------
    InvalidArgument
        An argument is not a finite number, or a duration is negative.
    """
    for name, v in (("kappa", kappa), ("mu", mu), ("eta", eta), ("active", active), ("inactive", inactive)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v)) or (
                name in ("active", "inactive") and v < 0):
            raise InvalidArgument(f"cycle_factor: {name} must be a finite number (a duration >= 0); got {v!r}")
    return float(kappa * math.exp(mu * inactive - eta * active))


def paper_factors(design: Any, h: Sequence[float] | None = None) -> tuple[float, ...]:
    """The paper's cycle factors ``f_ii`` (e:Fk, e:f11_le_delta_main), N channels.

    ``f_i = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` with ``tau = sum h``; with the design
    cycle's dead time ``d`` (blind after each switch, :mod:`switchobs_core.model.schedule`) channel i
    sees for ``h_i - d`` and is off for ``tau - h_i + d``.

    Parameters
    ----------
    design : CycleDesign
        Provides ``kappa``, ``eta``, ``mu`` (and ``cycle.h`` when ``h`` is None).
    h : sequence of float, optional
        Residence times ``h_1..h_N`` (default: the design's cycle).

    Returns
    -------
    tuple of float
        The paper claims convergence when every ``f_i < 1``: **not a proof** (module doc).
    """
    if h is None:
        if design.cycle is None:
            raise InvalidArgument("h is required for a design without a cycle (robust design)")
        h = design.cycle.h
    h = check_residences(h, len(design.kappa), allow_zero=True)
    tau = float(sum(h))
    d = design_dead_time(design)
    return tuple(cycle_factor(k, m, e, max(hi - d, 0.0), tau - max(hi - d, 0.0))
                 for k, m, e, hi in zip(design.kappa, design.mu, design.eta, h))


def design_dead_time(design: Any) -> float:
    """The dead time of the cycle a design was made for (0 for a robust design or none)."""
    cyc = getattr(design, "cycle", None)
    return float(getattr(cyc, "dead_time", 0.0) or 0.0)


def check_residences(h: Any, N: int, *, allow_zero: bool = False) -> tuple[float, ...]:
    """``h`` as N finite residence times > 0 (>= 0 with ``allow_zero``, tau > 0), or
    InvalidArgument naming ``h``."""
    try:
        hs = tuple(float(x) for x in h)
    except (TypeError, ValueError):
        raise InvalidArgument(f"h must be a sequence of {N} residence times; got {h!r}") from None
    ok = all(math.isfinite(x) and (x >= 0 if allow_zero else x > 0) for x in hs) and sum(hs) > 0
    if len(hs) != N or not ok:
        raise InvalidArgument(f"h must hold {N} finite residence times {'>= 0' if allow_zero else '> 0'}; "
                              f"got {hs}")
    return hs


@dataclass(frozen=True)
class EnvelopeRatio:
    """Worst case of ``||x_tilde_o^(i)(t)|| / z_i(t)`` over initial errors, per channel.

    Attributes
    ----------
    ratio : tuple of float
        ``max_t sigma_max(T_io' Phi(t, 0)) / (z_i(t) / z_i(0))``; > 1 means the paper's
        envelope z_i is exceeded by some initial error (the proof gap).
    t : tuple of float
        Time of the maximum.
    x0 : tuple of ndarray
        The unit initial error attaining it (top right singular vector).
    """

    ratio: tuple
    t: tuple
    x0: tuple
    horizon: float = 0.0


def envelope_ratio(system: Any, segments: Sequence[Segment], t_end: float, *,
                   dt: float = 0.002) -> EnvelopeRatio:
    """Worst-case excess of the paper's per-channel envelopes (the proof gap, see :mod:`switchobs_core.certificate`).

    With ``z_i(0^-) = ||x_tilde(0)||`` (the initial error bound), ``z_i(t) = g_i(t)
    ||x_tilde(0)||`` with ``g_i`` from (e:z1_evolution, e:z2_evolution), and
    ``x_tilde_o^(i)(t) = T_io' Phi(t, 0) x_tilde(0)`` exactly (continuous outputs). So

    .. math::

        \\max_{x_0 \\ne 0} \\frac{\\|T_{io}^T \\Phi(t,0) x_0\\|}{z_i(t)}
        = \\frac{\\sigma_{max}(T_{io}^T \\Phi(t, 0))}{g_i(t)},

    attained by the top right singular vector. The maximum is taken over a grid of
    step ``dt`` plus the switching instants, so the reported value is attained (a
    lower bound of the supremum over t). (With the tighter start ``z_i(0) =
    ||x_tilde_o^(i)(0)||`` the ratio is unbounded whenever ``T_io' L_j C_j x0 != 0`` for
    some ``x0`` in the unobservable subspace of channel i: ``z_i`` stays 0 while the other
    channel's correction pushes the error into channel i's observable subspace. The
    least-norm gains of our design happen not to couple that way on the paper's model.)

    Parameters
    ----------
    system : LTISystem
    segments : sequence of Segment
        The switching signal and designs (e.g. from
        :func:`switchobs_core.bounds.envelope.schedule_segments`).
    t_end : float
    dt : float

    Returns
    -------
    EnvelopeRatio
    """
    segments = list(segments)
    if not segments:
        raise InvalidArgument("segments: need at least one Segment")
    t0 = segments[0].t0
    t_end = as_finite(t_end, "t_end")
    if t_end <= t0:
        raise InvalidArgument(f"t_end must be > the first segment's start {t0}; got {t_end}")
    dt = as_finite(dt, "dt")
    if dt <= 0:
        raise InvalidArgument(f"dt must be > 0; got {dt}")
    grid = np.union1d(t0 + dt * np.arange(int((t_end - t0) / dt) + 1),
                      [s.t0 for s in segments if s.t0 <= t_end])
    Phis = error_transitions(system.A, system.C, grid, segments)
    g = envelope_z(grid, segments, 1.0)
    ratios, times, dirs = [], [], []
    for i in range(len(system.C)):
        T_o = system.decomposition(i + 1).T_o
        sv = np.linalg.norm(T_o.T[None] @ Phis, 2, axis=(1, 2))
        r = sv / g[i]
        k = int(np.argmax(r))
        _, _, Vt = np.linalg.svd(T_o.T @ Phis[k])
        ratios.append(float(r[k]))
        times.append(float(grid[k]))
        dirs.append(Vt[0])
    return EnvelopeRatio(ratio=tuple(ratios), t=tuple(times), x0=tuple(dirs), horizon=float(t_end))
