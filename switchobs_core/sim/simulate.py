"""Exact plant and observer simulation (Sections 2 and 7), seeded.

Two output settings:

*Continuous outputs* (``rate=None``), the paper's setting: ``y(t) = C_rho(t) x(t)``
is available at every instant. Between switching instants plant and observer form
the linear system

.. math::

    \\frac{d}{dt}\\begin{bmatrix} x \\\\ \\hat x \\end{bmatrix}
    = \\begin{bmatrix} A & 0 \\\\ L_i C_i & A - L_i C_i \\end{bmatrix}
      \\begin{bmatrix} x \\\\ \\hat x \\end{bmatrix}
    + \\begin{bmatrix} B \\\\ B \\end{bmatrix} u ,

propagated exactly by augmented matrix exponentials on the output grid (with ``u``
held on each grid step); the error then obeys (e:xtilde_dyn_piecewise) exactly.

*Sampled outputs* (``rate`` in Hz): the plant is advanced exactly to each sample time
``t_k = t0 + k / rate``, measured on the channel active at ``t_k`` (plus seeded noise),
and the observer integrates with the sample's innovation held (``hold="innovation"``,
the default) or the sample itself held (``hold="measurement"``). With innovation hold (and
every Kalman family) the samples go through :class:`~switchobs_core.runtime.observer.SwitchedObserver`
itself, the code the node runs, with its rounding-aware exact bound, and the plant is kept in
extended precision so the error column is the computed estimate's true error. Measurement
hold is the simulator's own code (direct ``expm`` of the augmented matrix, gains chosen from
the schedule's cycle index); with ``hold="innovation"`` that code (:func:`_simulate_sampled`)
is the tests' cross-implementation check of the observer.

Error transition with sampled outputs. With innovation hold one step maps the error by
``E = e^{A dt} - Gamma_A L C``, independent of the plant. With measurement hold, ``u = 0``
and no noise, one sample step ``dt`` with gain ``L`` maps ``(x, x_tilde)`` by

.. math::

    x^+ = e^{A dt} x, \\qquad
    \\tilde x^+ = \\Phi \\tilde x + (\\Phi + \\Gamma L C - e^{A dt}) x,

(``Phi, Gamma`` the ZOH pair of ``M = A - L C``): the held sample adds a term driven by
the plant state, of order ``dt^2``. :func:`sampled_error_transition` returns the two
blocks ``(Phi_ee, Phi_ex)`` of the product over the steps, so
``x_tilde(t) = Phi_ee x_tilde(0) + Phi_ex x(0)`` exactly.

Convergence to continuous outputs is first order in ``1 / rate``. Measured on the paper's
model, periodic (2 s, 0.6), first 20 s, error trajectories against continuous outputs:
innovation hold 0.36 % at 1 kHz and 3.6 % at 100 Hz, whatever the plant state; measurement
hold 10 % at 1 kHz for a unit-size plant state and 1 % for a plant state of 0.1 randn (the
held sample lags the moving plant); each 10x in rate divides these by 10.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..bounds.envelope import Segment, envelope_z
from ..bounds.envelope import alpha as _alpha
from ..exceptions import InvalidArgument
from ..families import family_entry, family_of_table
from ..model.schedule import PeriodicSchedule, RandomSchedule, SequenceSchedule, common_rows
from ..numerics.propagation import van_loan, zoh_pair
from ..numerics.rounding import EXPM_ULPS, UNIT_ROUNDOFF, ErrorEllipsoid, expm_error, gamma
from ..ranges import fmt_bytes
from ..runtime.observer import SwitchedObserver
from ..validation import as_finite, as_matrix
from .plant import Plant

__all__ = [
    "MAX_RESULT_BYTES",
    "SimulationResult",
    "simulate",
    "schedule_segments",
    "sampled_error_transition",
    "designs_for",
]


def _paper_gains(family: str) -> bool:
    """Whether the paper's envelopes apply to a family's gains (the registry's type says)."""
    return bool(family_entry(family).type().paper_envelope)


def designs_for(table: Any, schedule: Any, mode: str | None = None) -> tuple[str, list]:
    """Mode and per-cycle design list for ``schedule``: ``design(k) = designs[k % len]``.

    Periodic/sequence schedules look their cycles up in ``table``; a random (A2) schedule,
    or ``mode="robust"``, uses ``table.robust``.
    """
    if mode is None:
        if isinstance(schedule, RandomSchedule):
            mode = "robust"
        elif isinstance(schedule, PeriodicSchedule):
            mode = "periodic"
        elif isinstance(schedule, SequenceSchedule):
            mode = "sequence"
        else:
            raise InvalidArgument(f"schedule: cannot tell the mode of {type(schedule).__name__}; "
                                  "pass mode=")
    if mode not in ("periodic", "sequence", "robust"):
        raise InvalidArgument(f"mode must be periodic, sequence, robust or None; got {mode!r}")
    if mode == "robust":
        if getattr(table, "robust", None) is None:
            raise InvalidArgument("table has no robust design (table.robust is None)")
        return mode, [table.robust]
    return mode, [table.lookup(c) for c in schedule.cycles]


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


def _cycle_end_at(segments: Sequence[Segment], N: int, t_end: float) -> list[float]:
    """``[t_end]`` when the last cycle ends exactly at ``t_end`` (its last channel's residence
    ends there, so the next cycle's channel 1 would start at ``t_end``, outside the run), else
    ``[]``: a run of whole cycles reports every one of them (tolerance 1e-9 relative)."""
    last = segments[-1] if segments else None
    if last is not None and last.channel == N and abs(last.t1 - t_end) <= 1e-9 * max(1.0, abs(t_end)):
        return [float(t_end)]
    return []


def sampled_error_transition(A: np.ndarray, C: Sequence[np.ndarray],
                             steps: Sequence[tuple[float, int, np.ndarray]]
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Exact error transition of the sampled (ZOH) observer, ``u = 0``, no noise.

    Parameters
    ----------
    A : (n, n) ndarray
    C : sequence of (p_i, n) ndarray
    steps : sequence of (dt, channel, L)
        The sample steps in order: step length, channel held over it (1-based), gain.

    Returns
    -------
    Phi_ee, Phi_ex : (n, n) ndarray
        ``x_tilde(t) = Phi_ee x_tilde(0) + Phi_ex x(0)``. ``Phi_ee`` is the product of
        ``expm((A - L C) dt)``; ``Phi_ex`` collects the held-sample terms
        ``(Phi + Gamma L C - e^{A dt})`` (module docstring), zero for continuous outputs.
    """
    A = as_matrix(A, "A", square=True)
    n = A.shape[0]
    C = [as_matrix(Ci, f"C_{i + 1}", cols=n) for i, Ci in enumerate(C)]
    Pee, Pex, Pxx = np.eye(n), np.zeros((n, n)), np.eye(n)
    for k, step in enumerate(steps):
        try:
            dt, ch, L = step
        except (TypeError, ValueError):
            raise InvalidArgument(f"steps[{k}] must be (dt, channel, L); got {step!r}") from None
        if not (isinstance(ch, (int, np.integer)) and 1 <= ch <= len(C)):
            raise InvalidArgument(f"steps[{k}]: channel must be in 1..{len(C)}; got {ch!r}")
        Ci = C[ch - 1]
        L = as_matrix(L, f"steps[{k}] L", rows=n, cols=Ci.shape[0])
        Phi, Gamma = zoh_pair(A - L @ Ci, dt)
        F = expm(A * dt)
        D = Phi + Gamma @ L @ Ci - F
        Pee, Pex, Pxx = Phi @ Pee, Phi @ Pex + D @ Pxx, F @ Pxx
    return Pee, Pex


MAX_RESULT_BYTES = 2 * 2**30
"""Largest result (all output arrays) :func:`simulate` builds; longer runs are refused up front."""


@dataclass
class SimulationResult:
    """Arrays of one simulation (times along axis 0 unless said otherwise).

    Attributes
    ----------
    t : (T,) ndarray
    x, x_hat, error : (T, n) ndarray
        Plant state, estimate and ``x_tilde = x_hat - x`` (e:est_error).
    channel : (T,) ndarray of int
        Channel whose gain acts from ``t`` on (1-based).
    z : (N, T) ndarray
        The paper's envelopes (e:z1_evolution, e:z2_evolution), ``z_i(0^-) = e0``.
    paper_bound : (T,) ndarray
        ``alpha sum z_i``: the paper's claim (not a guarantee).
    exact_bound : (T,) ndarray
        ``||Phi(t, t0)|| e0`` with the rounding of the computation included (ours; see
        :mod:`switchobs_core.numerics.rounding`): a guarantee on :attr:`error` for noise-free continuous
        outputs and for noise-free sampled outputs with innovation hold (the default) or Kalman
        gains. With noise it is the *noise-free* bound, not a guarantee (:attr:`noisy`); with
        measurement hold it is the exact-arithmetic error-to-error part, see :attr:`hold_bound`.
    noise_bound : (T,) ndarray or None
        With a declared ``noise_max``: the observer's bound under any noise within it (ours).
    noisy : bool
        Measurement or process noise was drawn.
    hold_bound : (T,) ndarray or None
        Sampled outputs only: ``||Phi_ee|| e0 + ||Phi_ex|| ||x(0)||``, a guarantee for
        noiseless samples with ``u = 0`` (module docstring).
    xo_norms : (N, T) ndarray
        ``||x_tilde_o^(i)(t)|| = ||T_io' x_tilde(t)||`` (e:xtilde_decomp).
    switching_times : ndarray
        Switching instants used (for sampled outputs: the first sample of each interval).
    cycle_ends : ndarray
        Times at which a cycle ends (channel-1 starts after the first).
    alpha, e0 : float
    rate : float or None
    segments : list of Segment
    y : list of ndarray or None
        Sampled outputs only: the sample ``y_k`` (with noise) taken at ``t[k]``.
    """

    t: np.ndarray
    x: np.ndarray
    x_hat: np.ndarray
    error: np.ndarray
    channel: np.ndarray
    z: np.ndarray
    paper_bound: np.ndarray
    exact_bound: np.ndarray
    xo_norms: np.ndarray
    switching_times: np.ndarray
    cycle_ends: np.ndarray
    alpha: float
    e0: float
    rate: float | None
    segments: list = field(default_factory=list, repr=False)
    hold_bound: np.ndarray | None = None
    y: list | None = field(default=None, repr=False)
    family: str = "lmi"
    noise_bound: np.ndarray | None = None
    noisy: bool = False

    @property
    def paper(self) -> bool:
        """Whether the paper's envelopes apply to the gains of this run (its LMI family)."""
        return _paper_gains(self.family)

    @property
    def error_norm(self) -> np.ndarray:
        """``||x_tilde(t)||``, shape (T,)."""
        return np.linalg.norm(self.error, axis=1)

    def at(self, t: float) -> int:
        """Index of the last output time <= t."""
        return int(np.searchsorted(self.t, t, side="right") - 1)

    def guarantee(self) -> tuple[np.ndarray | None, str, str]:
        """The bound this run can honestly call guaranteed: ``(values, label, status)``.

        ``label`` names the column in one phrase ("guaranteed bound", "noise-free bound", ...);
        ``status`` says what it is and whether it held at every output (violations are counted
        with a relative tolerance of 1e-9; any violation makes it "NOT verified").

        - A declared noise bound (``noise_max``): the observer's ``noise_bound``.
        - Measurement hold: ``hold_bound`` (exact arithmetic; the plant-driven term included).
        - Noise without a declared bound: the exact bound is the *noise-free* bound, never
          called guaranteed (measurement noise: declare ``noise_max`` for a guarantee).
        - Otherwise: the exact bound, rounding included (:mod:`switchobs_core.numerics.rounding`).
        """
        en = self.error_norm

        def checked(b: np.ndarray, what: str) -> str:
            bad = en > b * (1 + 1e-9) + 1e-300
            n_bad = int(np.sum(bad))
            if n_bad:
                return (f"{what}: NOT verified: below the error at {n_bad} of {len(self.t)} outputs "
                        f"from t = {float(self.t[np.argmax(bad)]):.3g} s")
            return f"{what}: verified at all {len(self.t)} outputs"

        if self.noise_bound is not None:
            return self.noise_bound, "guaranteed bound (bounded noise)", checked(
                self.noise_bound, "||Phi|| e0 plus the declared noise's worst case, rounding included")
        if self.hold_bound is not None and self.paper and not self.noisy:
            return self.hold_bound, "guaranteed bound", checked(
                self.hold_bound, "||Phi_ee|| e0 + ||Phi_ex|| ||x(0)|| (measurement hold, noise-free, u = 0, "
                "exact arithmetic)")
        if self.noisy:
            return self.exact_bound, "noise-free bound", (
                "||Phi|| e0, the bound for noise-free outputs: NOT a guarantee for this run, whose outputs "
                "or plant are noisy (declare a measurement-noise bound, --noise-max, for one)")
        where = ("continuous outputs" if self.rate is None else "sampled outputs, innovation hold"
                 if self.paper else f"sampled outputs, {self.family} gains")
        return self.exact_bound, "guaranteed bound", checked(
            self.exact_bound, f"||Phi|| e0 with the computation's rounding ({where}, noise-free)")

    def summary(self) -> dict:
        """JSON-ready summary: final error, bounds and violations of the paper's bound."""
        en = self.error_norm
        paper = self.paper      # the paper's envelopes are for its LMI gains only
        viol = [int(np.sum(self.xo_norms[i] > self.z[i] * (1 + 1e-9))) for i in range(self.z.shape[0])]
        ends = [self.at(tc) for tc in self.cycle_ends]
        out = {
            "t_end": float(self.t[-1]),
            "rate_hz": self.rate,
            "e0": self.e0,
            "alpha": self.alpha,
            "final_error": float(en[-1]),
            "final_paper_bound": float(self.paper_bound[-1]),
            "final_exact_bound": float(self.exact_bound[-1]),
            # counted in every mode, with the tolerance stated here (relative 1e-9)
            "exact_bound_violations": int(np.sum(en > self.exact_bound * (1 + 1e-9) + 1e-300)),
            "paper_bound_violations": int(np.sum(en > self.paper_bound * (1 + 1e-9))),
            "envelope_violations": viol,
            "max_envelope_ratio": [float(np.max(self.xo_norms[i] / np.maximum(self.z[i], 1e-300)))
                                   for i in range(self.z.shape[0])],
            "cycle_end_errors": [float(en[j]) for j in ends],
            "cycles": len(self.cycle_ends),
            "gain_family": self.family,
            "noisy": self.noisy,
            "final_noise_bound": None if self.noise_bound is None else float(self.noise_bound[-1]),
            "noise_bound_violations": None if self.noise_bound is None else
            int(np.sum(en > self.noise_bound * (1 + 1e-9) + 1e-300)),
        }
        if not paper:
            for key in ("final_paper_bound", "paper_bound_violations", "envelope_violations", "max_envelope_ratio"):
                out[key] = None
        return out


def _u_at(u: Any, t: float, m: int) -> np.ndarray | None:
    if u is None:
        return None
    val = u(t) if callable(u) else u
    val = np.asarray(val, dtype=float).reshape(-1)
    if val.size != m:
        raise InvalidArgument(f"u must have m = {m} entries; got {val.size}")
    return val


def simulate(system: Any, table: Any, schedule: Any, x0: Any, xhat0: Any, t_end: float, *,
             rate: float | None = None, noise_std: float = 0.0, process_noise: Any = 0.0,
             seed: int = 0, mode: str | None = None, dt_out: float = 0.01,
             u: Any = None, e0: float | None = None, t0: float | None = None,
             hold: str = "innovation", noise_max: Any = None) -> SimulationResult:
    """Simulate plant and switched observer exactly (e:system, e:switched_observer).

    ``res = simulate(system, table, schedule, x0, xhat0, t_end, rate=None)``

    Parameters
    ----------
    system : LTISystem
    table : GainTable
        Designs, looked up per cycle of the schedule (``table.robust`` for robust mode).
    schedule : Schedule
        :mod:`switchobs_core.model.schedule` (periodic, sequence or random-A2).
    x0, xhat0 : (n,) array_like
        Initial plant state and estimate; ``x_tilde(0) = xhat0 - x0``.
    t_end : float
        End time in seconds (> t0).
    rate : float, optional
        Sample rate in Hz; None (default) is the paper's continuous-output setting.
    noise_std : float
        Measurement noise standard deviation (sampled outputs only).
    process_noise : float or (n, n) array_like
        See :class:`Plant`.
    seed : int
        Seed of every random draw.
    mode : {"periodic", "sequence", "robust"}, optional
        Default from the schedule type.
    dt_out : float
        Output grid step for continuous outputs (switching instants are added).
    u : (m,) array_like or callable ``t -> (m,)``, optional
        Input, held over each propagation step (ZOH).
    e0 : float, optional
        Initial error bound for the envelopes and the exact bound (default
        ``||xhat0 - x0||``).
    t0 : float, optional
        Start time (default ``schedule.t0``).
    hold : {"innovation", "measurement"}
        Sampled outputs: what the observer holds between samples (module docstring).
    noise_max : float or (N,) sequence, optional
        A declared bound on the measurement noise (per row, one value or one per channel):
        the noise draws are clipped to it and the result carries the observer's
        ``noise_bound`` (innovation hold and the Kalman families).

    Returns
    -------
    SimulationResult

    Raises
    ------
    InvalidArgument
        Bad sizes, ``t_end <= t0``, non-positive rate, noise with continuous outputs.
    """
    A = np.asarray(system.A, dtype=float)
    n = A.shape[0]
    B = np.asarray(system.B, dtype=float)
    B = B.reshape(n, -1) if B.size else np.zeros((n, 0))
    C = tuple(np.asarray(Ci, dtype=float) for Ci in system.C)
    N = len(C)
    x0 = np.array(x0, dtype=float).reshape(-1)
    xhat0 = np.array(xhat0, dtype=float).reshape(-1)
    for name, v in (("x0", x0), ("xhat0", xhat0)):
        if v.size != n or not np.isfinite(v).all():
            raise InvalidArgument(f"{name} must hold n = {n} finite entries; got {v.size}")
    t0 = float(schedule.t0 if t0 is None else t0)
    t_end = float(t_end)
    if not (math.isfinite(t_end) and t_end > t0):
        raise InvalidArgument(f"t_end must be a finite time > t0 = {t0}; got {t_end}")
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise InvalidArgument(f"rate must be a positive number of Hz or None; got {rate}")
    if rate is None and noise_std:
        raise InvalidArgument("noise_std needs sampled outputs (pass rate=HZ); continuous white "
                              "measurement noise is not modelled")
    if not (math.isfinite(noise_std) and noise_std >= 0):
        raise InvalidArgument(f"noise_std must be >= 0; got {noise_std}")
    if hold not in ("innovation", "measurement"):
        raise InvalidArgument(f"hold must be 'innovation' or 'measurement'; got {hold!r}")
    if not (math.isfinite(dt_out) and dt_out > 0):
        raise InvalidArgument(f"dt_out must be > 0; got {dt_out}")
    pts = (t_end - t0) * (rate if rate is not None else 1.0 / dt_out) + 1
    need = pts * 8.0 * (4 * n + len(C) + 8)  # x, x_hat, error, y, xo_norms, bounds, channel
    if need > MAX_RESULT_BYTES:
        raise InvalidArgument(f"simulate would hold {fmt_bytes(need)} of results for t_end - t0 = "
                              f"{t_end - t0:g} s ({pts:.3g} output points; limit {MAX_RESULT_BYTES / 2**30:.0f} GiB): "
                              "shorten the run (--t-end) or lower the rate (--rate); from Python also raise dt_out")
    # e0: the computed ||xhat0 - x0|| inflated by its own rounding, so that it bounds the true one
    e0 = float(np.linalg.norm(xhat0 - x0)) * (1.0 + gamma(n + 3)) if e0 is None else float(e0)
    if noise_max is not None and (rate is None or hold != "innovation"):
        raise InvalidArgument("noise_max (a declared noise bound) needs sampled outputs with innovation hold "
                              "(--rate HZ, --hold innovation)")
    if not _paper_gains(family_of_table(table)) or (rate is not None and hold == "innovation"):
        return _simulate_observer(system, table, schedule, x0, xhat0, t0, t_end, rate, noise_std, process_noise,
                                  seed, mode, u, e0, noise_max)
    mode, designs = designs_for(table, schedule, mode)
    segments = schedule_segments(schedule, designs, t_end)
    T_o = [system.decomposition(i + 1).T_o for i in range(N)]
    try:
        alpha_ = float(system.alpha)
    except AttributeError:
        alpha_ = _alpha(T_o)
    if rate is None:
        t, X, Xh, ch, exact = _simulate_continuous(A, B, C, segments, x0, xhat0, t0, t_end, dt_out, u,
                                                   process_noise, seed, e0)
        eff_segments = segments
        hold_b = ys = None
    else:
        t, X, Xh, ch, exact, hold_b, eff_segments, ys = _simulate_sampled(
            A, B, C, segments, x0, xhat0, t0, t_end, rate, u, process_noise, noise_std, seed, e0, hold)
    err = Xh - X
    z = envelope_z(t, eff_segments, e0)
    xo = np.stack([np.linalg.norm(err @ Ti, axis=1) for Ti in T_o])
    sw = np.array([s.t0 for s in eff_segments if s.starts_residence])
    ends = np.array([s.t0 for s in eff_segments if s.channel == 1 and s.starts_residence and s.t0 > eff_segments[0].t0]
                    + _cycle_end_at(eff_segments, N, t_end))
    return SimulationResult(t=t, x=X, x_hat=Xh, error=err, channel=ch, z=z,
                            paper_bound=alpha_ * z.sum(axis=0), exact_bound=exact, xo_norms=xo,
                            switching_times=sw, cycle_ends=ends, alpha=alpha_, e0=e0,
                            rate=rate, segments=eff_segments, hold_bound=hold_b, y=ys)


def _simulate_observer(system, table, schedule, x0, xhat0, t0, t_end, rate, noise_std, process_noise, seed, mode,
                       u, e0, noise_max) -> SimulationResult:
    """Sampled outputs through :class:`SwitchedObserver` itself, the code the node runs (innovation
    hold with LMI gains, and every Kalman family), against an extended-precision plant.

    The plant is :class:`Plant` with ``extended=True`` (the reference of
    :mod:`switchobs_core.numerics.rounding`): ``x`` is its state rounded once to double, and ``error``
    is ``x_hat - x`` taken in extended precision, so the exact bound (which includes the
    observer's rounding) is checked against the error of the computed estimate, not against
    the simulator's own rounding. The paper's envelopes are the observer's (LMI gains; for the
    Kalman gains ``z`` and ``paper_bound`` are :data:`~switchobs_core.runtime.observer.NOT_APPLICABLE`).
    """
    if rate is None:
        raise InvalidArgument("a kalman gain table is a sampled filter: pass --rate HZ")
    if mode is None:
        mode = ("robust" if isinstance(schedule, RandomSchedule) else
                "periodic" if isinstance(schedule, PeriodicSchedule) else "sequence")
    cycles = None if mode == "robust" else list(schedule.cycles)
    obs = SwitchedObserver(system, table, mode, cycles, x0=xhat0, t0=t0, e0=e0, noise_max=noise_max)
    plant = Plant(system, x0, seed=seed, process_noise=process_noise, t0=t0, extended=True)
    vmax = None if noise_max is None else np.broadcast_to(np.asarray(noise_max, dtype=float), (system.N,))
    K = int(math.floor((t_end - t0) * rate + 1e-9))
    n, N = system.n, system.N
    t = t0 + np.arange(K + 1) / rate
    X, Xh, err = np.empty((K + 1, n)), np.empty((K + 1, n)), np.empty((K + 1, n))
    ch, exact = np.empty(K + 1, dtype=int), np.empty(K + 1)
    noise_b = None if noise_max is None else np.empty(K + 1)
    z, paper = np.empty((N, K + 1)), np.empty(K + 1)
    ys = []
    blind_rows = None
    if any(c.dead_time for c in getattr(schedule, "cycles", [])):
        blind_rows = common_rows(system.C)
        if not blind_rows:
            raise InvalidArgument("a dead time with channels that share no output row: nothing is measured while "
                                  "blind, which simulate does not model; use channels with common rows")
    for k, tk in enumerate(t):
        uk = _u_at(u, tk, plant.B.shape[1])
        X[k] = plant.advance(tk, uk)
        ch[k] = c = schedule.channel_at(tk)
        y = plant.measure(c, noise_std, noise_max=None if vmax is None else float(vmax[c - 1]))
        rows = blind_rows if blind_rows is not None and schedule.blind_at(tk) else None
        if rows is not None:            # the dead time after a switch: only the shared rows
            y = y[list(rows)]
        ys.append(y)
        Xh[k] = xh = obs.update(tk, c, y, u=uk, rows=rows)
        err[k] = np.asarray(xh - plant.x_extended, dtype=float)
        env = obs.envelope()
        exact[k], z[:, k], paper[k] = env.exact_bound, env.z, env.paper_bound
        if noise_b is not None:
            noise_b[k] = env.noise_bound
    T_o = [system.decomposition(i + 1).T_o for i in range(N)]
    sw = t[np.r_[True, ch[1:] != ch[:-1]]]
    ends = t[1:][(ch[1:] == 1) & (ch[:-1] != 1)]
    return SimulationResult(t=t, x=X, x_hat=Xh, error=err, channel=ch, z=z, paper_bound=paper, exact_bound=exact,
                            xo_norms=np.stack([np.linalg.norm(err @ Ti, axis=1) for Ti in T_o]),
                            switching_times=sw, cycle_ends=ends, alpha=float(system.alpha), e0=e0, rate=rate,
                            family=obs.family, y=ys, noise_bound=noise_b,
                            noisy=bool(noise_std) or bool(np.any(plant.Qc)))


def _simulate_continuous(A, B, C, segments, x0, xhat0, t0, t_end, dt_out, u, process_noise, seed, e0):
    """Joint (x, x_hat) propagation between grid points and switching instants, with the exact
    bound of the *computed* pair.

    Bound (the argument of :mod:`switchobs_core.numerics.rounding` on the joint step): the computed pair
    obeys ``z_{k+1} = fl(J~ z_k)`` with ``J~`` the computed ``e^{J dt}``; the exact joint map
    keeps ``x_hat - x`` on ``e_{k+1} = E e_k`` (``E = e^{(A - L C) dt}``, the lower-right block
    of ``e^{J dt}``, since ``J`` is block triangular). Hence the computed difference obeys
    ``e_{k+1} = H~ e_k + r_k`` with ``H~`` the computed lower-right block and
    ``||r_k|| <= sqrt(2) (eps_J + gamma_{2n+2} ||J~||_F) ||z_k|| + eps_J ||e_k||`` (``eps_J``
    from :func:`~switchobs_core.numerics.rounding.expm_error`), plus the input's term; an
    :class:`~switchobs_core.numerics.rounding.ErrorEllipsoid` keeps ``||e_k||``. The bound covers the
    error column as computed (``x_hat - x`` rounded, a factor ``1 + 2u``): the difference between
    the computed estimate and the computed plant that drives it.
    """
    n, m = B.shape
    grid = t0 + dt_out * np.arange(int(math.floor((t_end - t0) / dt_out + 1e-9)) + 1)
    grid = np.union1d(grid[grid <= t_end], [s.t0 for s in segments] + [t_end])
    Qc = np.asarray(process_noise, dtype=float)
    if Qc.ndim == 0:
        Qc = float(Qc) ** 2 * np.eye(n)
    noisy = bool(np.any(Qc))
    rng = np.random.default_rng(seed)
    Qj = np.zeros((2 * n, 2 * n))
    Qj[:n, :n] = Qc
    Bj = np.vstack([B, B])
    zc = np.concatenate([x0, xhat0])
    out = np.empty((grid.size, 2 * n))
    ch = np.empty(grid.size, dtype=int)
    cache: dict = {}
    si = 0
    ell = ErrorEllipsoid(n, e0)
    exact = np.empty(grid.size)
    g2n, gm = gamma(2 * n + 2), gamma(m + 2)
    for k, tk in enumerate(grid):
        if k > 0:
            ta = grid[k - 1]
            seg = segments[si]
            dt = tk - ta
            key = (id(seg.design), seg.channel, seg.part, dt)
            step = cache.get(key)
            if step is None:
                Ci = C[seg.channel - 1]
                L = seg.L
                J = np.zeros((2 * n, 2 * n))
                J[:n, :n] = A
                J[n:, :n] = L @ Ci
                J[n:, n:] = A - L @ Ci
                Phi, Gam = zoh_pair(J, dt)
                Lq = None
                if noisy:
                    _, Qd = van_loan(J, Qj, dt)
                    w, V = np.linalg.eigh(Qd)
                    Lq = V * np.sqrt(np.clip(w, 0, None))
                GB = Gam @ Bj
                eps = expm_error(J, dt, Phi)
                fGB = float(np.linalg.norm(GB))
                # the input's effect on x_hat - x is 0 exactly; computed: the rows' difference,
                # the expm model's error of Gamma and the rounding of GB u
                du = float(np.linalg.norm(GB[n:] - GB[:n])) + (2 * EXPM_ULPS * (2 * n + m) * UNIT_ROUNDOFF + gm) * fGB
                step = cache[key] = (Phi, GB, Lq, np.ascontiguousarray(Phi[n:, n:]), eps,
                                     math.sqrt(2.0) * (eps + g2n * float(np.linalg.norm(Phi))), du)
            Phi, GB, Lq, H, eps, rz, du = step
            rho = rz * math.sqrt(float(zc @ zc)) + eps * ell.trace_bound()
            zc = Phi @ zc
            uk = _u_at(u, ta, m)
            if uk is not None:
                zc += GB @ uk
                rho += du * math.sqrt(float(uk @ uk))
            if Lq is not None:
                zc += Lq @ rng.standard_normal(2 * n)
            ell.step(H, rho * (1.0 + gamma(8)))
        while si + 1 < len(segments) and segments[si + 1].t0 <= tk:
            si += 1
        out[k] = zc
        ch[k] = segments[si].channel
        exact[k] = ell.bound() * (1.0 + 2.0 * UNIT_ROUNDOFF)
    return grid, out[:, :n], out[:, n:], ch, exact


def _simulate_sampled(A, B, C, segments, x0, xhat0, t0, t_end, rate, u, process_noise,
                      noise_std, seed, e0, hold_mode="innovation"):
    """Plant advanced exactly to each sample; observer with the innovation or the sample held."""
    n, m = B.shape
    K = int(math.floor((t_end - t0) * rate + 1e-9))
    ts = t0 + np.arange(K + 1) / rate

    class _S:  # minimal system view for Plant
        pass

    sysv = _S()
    sysv.A, sysv.B, sysv.C = A, B, C
    plant = Plant(sysv, x0, seed=seed, process_noise=process_noise, t0=t0)
    X = np.empty((ts.size, n))
    Xh = np.empty((ts.size, n))
    ch = np.empty(ts.size, dtype=int)
    exact = np.empty(ts.size)
    hold = np.empty(ts.size)
    xh = xhat0.copy()
    Pee, Pex, Pxx = np.eye(n), np.zeros((n, n)), np.eye(n)
    x0n = float(np.linalg.norm(x0))
    cache: dict = {}
    si = 0
    eff: list[Segment] = []
    held = None  # (seg, y, u)
    ys: list = []
    for k, tk in enumerate(ts):
        if k > 0:
            dt = tk - ts[k - 1]
            seg, y, uh = held
            key = (id(seg.design), seg.channel, seg.part, dt)
            step = cache.get(key)
            if step is None:
                Ci = C[seg.channel - 1]
                L = seg.L
                F = expm(A * dt)
                if hold_mode == "innovation":
                    # x_hat+ = F x_hat + Gamma_A (L nu + B u); error map E = F - Gamma_A L C, D = 0
                    _, GamA = zoh_pair(A, dt)
                    GL = GamA @ L
                    step = cache[key] = (F, GL, GamA @ B, F - GL @ Ci, np.zeros((n, n)), F)
                else:
                    Phi, Gam = zoh_pair(A - L @ Ci, dt)
                    step = cache[key] = (Phi, Gam @ L, Gam @ B, Phi, Phi + Gam @ L @ Ci - F, F)
            Phi, GL, GB, E, D, F = step
            xh = Phi @ xh + GL @ y
            if uh is not None:
                xh = xh + GB @ uh
            Pee, Pex, Pxx = E @ Pee, E @ Pex + D @ Pxx, F @ Pxx
        uk = _u_at(u, tk, m)
        x = plant.advance(tk, held[2] if held is not None else None) if k > 0 else plant.x
        while si + 1 < len(segments) and segments[si + 1].t0 <= tk:
            si += 1
        seg = segments[si]
        if not eff or eff[-1].channel != seg.channel or eff[-1].design is not seg.design or eff[-1].part != seg.part:
            if eff:
                eff[-1] = Segment(eff[-1].t0, tk, eff[-1].channel, eff[-1].design, eff[-1].part)
            eff.append(Segment(tk, math.inf, seg.channel, seg.design, seg.part))
        y = plant.measure(seg.channel, noise_std)
        ys.append(y)
        held = (seg, y - C[seg.channel - 1] @ xh if hold_mode == "innovation" else y, uk)
        X[k], Xh[k], ch[k] = x, xh, seg.channel
        exact[k] = np.linalg.norm(Pee, 2) * e0
        hold[k] = exact[k] + np.linalg.norm(Pex, 2) * x0n
    eff[-1] = Segment(eff[-1].t0, math.inf, eff[-1].channel, eff[-1].design, eff[-1].part)
    return ts, X, Xh, ch, exact, hold, eff, ys
