"""The paper's envelopes z_i, alpha and error bound, and the exact transition bound.

Two kinds of bound on the estimation error ``x_tilde = x_hat - x`` (e:est_error) live
here, and they must not be confused:

*The paper's bound* (Section 4, Theorem ``t:xtilde_bound``). Scalar envelopes
``z_i`` evolve by (e:z1_evolution)/(e:z2_evolution), written for N channels:

.. math::

    z_i(t) = \\begin{cases}
      \\kappa_i e^{-\\eta_i (t - t_{on})} z_i(t_{on}^-) & \\text{channel } i \\text{ active}, \\\\
      e^{\\mu_i (t - t_{off})} z_i(t_{off}) & \\text{otherwise},
    \\end{cases}

and the paper claims ``||x_tilde(t)|| <= alpha * sum_i z_i(t)`` (e:xtilde_alpha_z_main),
with ``alpha = 1 / sigma_min(H)``, ``H = [T_1o'; ...; T_No']`` (e:alpha_def).
**This is not a guarantee.** The proof assumes that while channel j is active the
observable error of channel i != j evolves by ``A_o^(i)`` alone
(e:xo1_dynamics_piecewise); in fact
``d/dt x_o^(i) = A_o^(i) x_o^(i) - T_io' L_j C_j x_tilde``, and ``T_io' L_j != 0`` when
observable subspaces overlap (the cross term that e:xo1_dynamics_piecewise omits). ``z_i`` can be exceeded; see
:func:`switchobs_core.certificate.envelope_ratio` for the worst case.

*The exact bound* (ours). In the paper's continuous-output setting the error obeys
(e:xtilde_dyn_piecewise) exactly, so ``x_tilde(t) = Phi(t, 0) x_tilde(0)`` with
``Phi(t, 0)`` the ordered product of ``expm((A - L_i C_i) dt)`` over the intervals,
and ``||x_tilde(t)|| <= ||Phi(t, 0)|| e0`` for every ``||x_tilde(0)|| <= e0``, with
equality for the top right singular vector of ``Phi(t, 0)``. That is a guarantee
(up to floating-point rounding in expm) for continuous outputs. For sampled outputs the
online observer's ``Phi`` is the product of its per-sample error maps: with the default
innovation hold, ``e^{A dt} - Gamma_A L C``, exact for noise-free samples, so the bound is
a guarantee there too; with measurement hold it is only the error-to-error block and the
error has a further term driven by the plant trajectory
(:func:`switchobs_core.sim.simulate.sampled_error_transition` gives it). Every such bound
assumes ``||x_tilde(t0)|| <= e0`` at the time origin and noise-free outputs.

Envelope convention: ``z_i(0^-) = e0`` for every channel (an initial error bound,
``||x_o^(i)(0)|| <= ||x_tilde(0)|| <= e0``); at an activation the envelope jumps to
``kappa_i z_i(t_on^-)``, which is how the recursion (e:Fz_system), (e:Fk) reads the
piecewise definition.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument
from ..numerics.propagation import transition
from ..validation import as_finite, as_matrix, as_vector

__all__ = [
    "Envelope",
    "Segment",
    "schedule_segments",
    "alpha",
    "EnvelopeTracker",
    "envelope_z",
    "paper_bound",
    "error_transitions",
    "exact_bound",
]


@dataclass(frozen=True, init=False)
class Envelope:
    """Bounds on ``||x_tilde(t)||`` at one time.

    Attributes
    ----------
    z : (N,) ndarray
        The paper's envelopes ``z_1..z_N`` (e:z1_evolution, e:z2_evolution).
    paper_bound : float
        ``alpha * sum(z)`` (e:xtilde_alpha_z_main): **the paper's claim, not a guarantee**.
    exact_bound : float
        ``||Phi(t, t0)|| e0``: ours; a guarantee for continuous outputs and for sampled
        outputs with innovation hold, given ``||x_tilde(t0)|| <= e0`` and noise-free outputs
        (module docstring; with measurement hold see the simulator's ``hold_bound``).
    t : float
        Time the bounds refer to.
    noise_bound : float or None
        With a declared bound on the measurement noise (``noise_max``): a rigorous bound on the
        error of the computed estimate under any noise within it (ours; rounding included).
        None when no noise bound is declared; then ``exact_bound`` is the *noise-free* bound.
    """

    z: np.ndarray
    paper_bound: float
    exact_bound: float
    t: float = 0.0
    noise_bound: float | None = None

    def __init__(self, z: np.ndarray, paper_bound: float, exact_bound: float, t: float = 0.0,
                 noise_bound: float | None = None) -> None:
        # the fields into the instance's dict (frozen: no __setattr__): half the time of the dataclass's five
        # object.__setattr__ calls (one envelope per published sample)
        d = self.__dict__
        d["z"], d["paper_bound"], d["exact_bound"] = z, paper_bound, exact_bound
        d["t"], d["noise_bound"] = t, noise_bound


@dataclass(frozen=True)
class Segment:
    """One interval ``[t0, t1)`` on which ``channel`` (1-based) is active with ``design``.

    ``design`` is any object with per-channel sequences ``L`` (n x p_i gains), ``kappa``,
    ``eta`` and ``mu`` (a :class:`switchobs_core.table.gains.CycleDesign`). ``part`` is ``"blind"``
    for the dead time after a switching instant (the LMI observer applies no gain: ``L = 0``),
    ``"seeing"`` for the rest of that residence, ``""`` for a residence without a dead time.
    """

    t0: float
    t1: float
    channel: int
    design: Any
    part: str = ""

    def __post_init__(self) -> None:
        t0 = as_finite(self.t0, "t0")
        t1 = float(self.t1)
        if math.isnan(t1) or t1 < t0:
            raise InvalidArgument(f"t1 must be >= t0 = {t0}; got {self.t1!r}")
        kappa = getattr(self.design, "kappa", None)
        N = len(kappa) if kappa is not None else None
        if not isinstance(self.channel, (int, np.integer)) or self.channel < 1 or (N and self.channel > N):
            raise InvalidArgument(f"channel must be a channel number in 1..{N or 'N'}; got {self.channel!r}")

    @property
    def L(self) -> np.ndarray:
        """The gain ``L_i`` of the active channel (zero in a blind part)."""
        L = np.asarray(self.design.L[self.channel - 1], dtype=float)
        return np.zeros_like(L) if self.part == "blind" else L

    @property
    def starts_residence(self) -> bool:
        """Whether ``t0`` is a switching instant (not the end of a dead time)."""
        return self.part != "seeing"


def schedule_segments(schedule: Any, designs: Sequence[Any], t_end: float) -> list[Segment]:
    """The active intervals of ``schedule`` on ``[t0, t_end)``; cycle k uses ``designs[k % K]``."""
    t_end = as_finite(t_end, "t_end")
    designs = list(designs)
    if not designs:
        raise InvalidArgument("designs: need at least one design")
    segs: list[Segment] = []
    t, k = float(schedule.t0), 0
    while t < t_end:
        c = schedule.cycle(k)
        d = designs[k % len(designs)]
        dead = c.dead_time
        for i, h in enumerate(c.h):
            if t >= t_end:
                break
            if dead:        # the blind interval after the switch (L = 0), then the rest
                segs.append(Segment(t, t + dead, i + 1, d, "blind"))
                segs.append(Segment(t + dead, t + h, i + 1, d, "seeing"))
            else:
                segs.append(Segment(t, t + h, i + 1, d))
            t += h
        k += 1
    return segs


def alpha(T_o: Sequence[np.ndarray]) -> float:
    """``alpha = 1 / sigma_min(H)``, ``H = [T_1o'; ...; T_No']`` (e:alpha_def).

    Parameters
    ----------
    T_o : sequence of (n, r_i) array_like
        Orthonormal bases of the observable subspaces of (A, C_i).

    Returns
    -------
    float
        alpha >= 1 (Theorem ``t:xtilde_bound``, Step 3).

    Raises
    ------
    InvalidArgument
        If H is rank deficient ((A, [C_1; ...; C_N]) unobservable, A1 fails).
    """
    T_o = list(T_o)
    if not T_o:
        raise InvalidArgument("T_o: need the observable bases of N >= 1 channels; got none")
    mats = [as_matrix(T, f"T_o[{i}]", exc=InvalidArgument) for i, T in enumerate(T_o)]
    n = mats[0].shape[0]
    for i, T in enumerate(mats):
        if T.shape[0] != n:
            raise InvalidArgument(f"T_o[{i}] has {T.shape[0]} rows; T_o[0] has {n} (every T_io is n x r_i)")
    H = np.vstack([T.T for T in mats])
    if H.shape[0] < H.shape[1]:
        raise InvalidArgument(f"T_o: H = [T_1o'; ...] has {H.shape[0]} rows < n = {H.shape[1]}; "
                              "the channels together are not observable (A1)")
    smin = np.linalg.svd(H, compute_uv=False)[-1]
    if smin <= 1e-12:
        raise InvalidArgument("T_o: H = [T_1o'; ...] is rank deficient; A1 fails")
    return float(1.0 / smin)


def paper_bound(z: np.ndarray, alpha_: float) -> np.ndarray:
    """The paper's claimed bound ``alpha * sum_i z_i`` (e:xtilde_alpha_z_main); not a guarantee."""
    a = as_finite(alpha_, "alpha_")
    if a < 0:
        raise InvalidArgument(f"alpha_ must be >= 0; got {a}")
    z = np.asarray(z, dtype=float)
    if not np.isfinite(z).all():
        raise InvalidArgument("z has a non-finite entry")
    return a * np.sum(z, axis=0)


def exact_bound(Phi: np.ndarray, e0: float) -> float:
    """``||Phi(t, 0)||_2 * e0``: the exact worst-case error over ``||x_tilde(0)|| <= e0``."""
    Phi = as_matrix(Phi, "Phi", square=True)
    return float(np.linalg.norm(Phi, 2) * _check_e0(e0))


class EnvelopeTracker:
    """Online evaluation of the paper's envelopes ``z_i`` (e:z1_evolution, e:z2_evolution).

    Each ``z_i`` is stored as an anchor ``(t_a, z_a)`` and a rate ``r_i``
    (``-eta_i`` while active, ``mu_i`` while inactive), so ``z_i(t) = z_a e^{r_i (t - t_a)}``
    costs nothing between switching instants.

    Parameters
    ----------
    mu : (N,) array_like
        Log norms ``mu_i`` of ``A_o^(i)`` (e:mu_o_i_def).
    z0 : float
        Initial value ``z_i(0^-)`` for every channel.
    t0 : float
        Initial time.
    """

    def __init__(self, mu: Sequence[float], z0: float, t0: float = 0.0):
        self.mu = as_vector(mu, "mu").copy()
        z0 = float(z0)
        if not (math.isfinite(z0) and z0 >= 0):
            raise InvalidArgument(f"z0 must be a finite number >= 0; got {z0}")
        t0 = as_finite(t0, "t0")
        self.N = self.mu.size
        self.t_a = np.full(self.N, float(t0))
        self.z_a = np.full(self.N, float(z0))
        self.rate = self.mu.copy()
        self.active = 0  # 1-based; 0 = none yet

    _pending: tuple | None = None

    def z(self, t: float) -> np.ndarray:
        """``z_1(t)..z_N(t)`` (t at or after the last switching instant)."""
        if self._pending is not None and t >= self._pending[0]:
            t_on, j, kappa, eta = self._pending
            self._pending = None
            self.z_a = self.z_a * np.exp(self.rate * (t_on - self.t_a))
            self.t_a[:] = t_on
            self._activate(j, kappa, eta)
        return self.z_a * np.exp(self.rate * (t - self.t_a))

    def switch(self, t: float, channel: int, kappa: Sequence[float], eta: Sequence[float],
               mu: Sequence[float] | None = None, dead_time: float = 0.0) -> None:
        """Channel ``channel`` (1-based) becomes active at ``t`` with the design's ``kappa``, ``eta``.

        With a ``dead_time`` d > 0 the channel is blind until ``t + d`` (every ``z_i`` grows at
        ``mu_i``, the extra inactive interval of :mod:`switchobs_core.model.schedule`) and becomes
        active then (evaluated lazily by :meth:`z`, whose times never go back)."""
        if not isinstance(channel, (int, np.integer)) or not 1 <= channel <= self.N:
            raise InvalidArgument(f"channel must be in 1..{self.N}; got {channel!r}")
        zt = self.z(t)
        if mu is not None:
            self.mu = np.asarray(mu, dtype=float).copy()
        self.t_a[:] = t
        self.z_a = zt
        self.rate = self.mu.copy()
        self.active = channel
        self._pending = None
        if dead_time > 0:
            self._pending = (t + float(dead_time), channel - 1, float(kappa[channel - 1]), float(eta[channel - 1]))
            return
        self._activate(channel - 1, float(kappa[channel - 1]), float(eta[channel - 1]))

    def _activate(self, j: int, kappa: float, eta: float) -> None:
        self.rate[j] = -eta
        self.z_a[j] = kappa * self.z_a[j]


def envelope_z(t: np.ndarray, segments: Sequence[Segment], z0: float) -> np.ndarray:
    """The paper's envelopes on a time grid.

    Parameters
    ----------
    t : (T,) array_like
        Nondecreasing times, ``t[0] >= segments[0].t0``.
    segments : sequence of Segment
        Consecutive active intervals (the switching signal and the designs used).
    z0 : float
        ``z_i(0^-)``, normally the initial error bound e0.

    Returns
    -------
    (N, T) ndarray
        ``z_i(t_k)``; at a switching instant the value after the jump.
    """
    t = _times(t)
    segments = _segments(segments)
    z0 = float(z0)
    if not (math.isfinite(z0) and z0 >= 0):
        raise InvalidArgument(f"z0 must be a finite number >= 0; got {z0}")
    d0 = segments[0].design
    tracker = EnvelopeTracker(d0.mu, z0, segments[0].t0)
    out = np.empty((len(d0.mu), t.size))
    k = 0
    for idx, seg in enumerate(segments):
        if seg.part == "blind":         # active from its seeing part on
            tracker.switch(seg.t0, seg.channel, seg.design.kappa, seg.design.eta, seg.design.mu,
                           dead_time=seg.t1 - seg.t0)
        elif seg.part == "":
            tracker.switch(seg.t0, seg.channel, seg.design.kappa, seg.design.eta, seg.design.mu)
        last = idx == len(segments) - 1
        while k < t.size and (t[k] < seg.t1 or last):
            out[:, k] = tracker.z(t[k])
            k += 1
    return out


def _grid_with_breaks(t: np.ndarray, segments: Sequence[Segment]):
    """Yield (segment, t_start, t_end, record_index_or_None) steps covering ``t``."""
    k = 0
    for idx, seg in enumerate(segments):
        last = idx == len(segments) - 1
        tc = seg.t0
        while k < t.size and (t[k] < seg.t1 or last):
            yield seg, tc, t[k], k
            tc = t[k]
            k += 1
        if not last and tc < seg.t1:
            yield seg, tc, seg.t1, None


def error_transitions(A: np.ndarray, C: Sequence[np.ndarray], t: np.ndarray,
                      segments: Sequence[Segment]) -> np.ndarray:
    """Error transition matrices ``Phi(t_k, t_0)`` of (e:xtilde_dyn_piecewise).

    ``Phi(t, t_0)`` is the ordered product of ``expm((A - L_i C_i) dt)`` over the
    pieces of ``[t_0, t]`` cut at the switching instants; ``x_tilde(t) = Phi(t, t_0)
    x_tilde(t_0)`` exactly in the continuous-output setting.

    Parameters
    ----------
    A : (n, n) ndarray
    C : sequence of (p_i, n) ndarray
        Output matrices, ``C[i - 1]`` for channel i.
    t : (T,) array_like
        Output times, nondecreasing, ``t[0] >= segments[0].t0``.
    segments : sequence of Segment

    Returns
    -------
    (T, n, n) ndarray
    """
    A = as_matrix(A, "A", square=True)
    n = A.shape[0]
    C = [as_matrix(Ci, f"C_{i + 1}", cols=n) for i, Ci in enumerate(C)]
    t = _times(t)
    segments = _segments(segments)
    out = np.empty((t.size, n, n))
    Phi = np.eye(n)
    cache: dict = {}
    for seg, ta, tb, k in _grid_with_breaks(t, segments):
        dt = tb - ta
        if dt > 0:
            key = (id(seg.design), seg.channel, seg.part, dt)
            E = cache.get(key)
            if E is None:
                M = A - seg.L @ np.asarray(C[seg.channel - 1], dtype=float)
                E = cache[key] = transition(M, dt)
            Phi = E @ Phi
        if k is not None:
            out[k] = Phi
    return out


def _times(t: Any) -> np.ndarray:
    t = np.asarray(t, dtype=float).reshape(-1)
    if not np.isfinite(t).all():
        raise InvalidArgument("t has a non-finite time")
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise InvalidArgument("t must be nondecreasing")
    return t


def _segments(segments: Any) -> list:
    segments = list(segments)
    if not segments:
        raise InvalidArgument("segments: need at least one Segment")
    return segments


def _check_e0(e0: float) -> float:
    e0 = float(e0)
    if not (math.isfinite(e0) and e0 >= 0):
        raise InvalidArgument(f"e0 must be a finite number >= 0; got {e0}")
    return e0
