"""Exact plant and observer simulation (Sections 2 and 7), seeded.

Two output settings:

*Continuous outputs* (``rate=None``), the paper's setting: ``y(t) = C_rho(t) x(t)`` is
available at every instant, and plant and observer form one linear system between switching
instants, propagated exactly (:mod:`switchobs_core.sim.continuous`); the error obeys
(e:xtilde_dyn_piecewise) exactly.

*Sampled outputs* (``rate`` in Hz): the plant is advanced exactly to each sample time
``t_k = t0 + k / rate`` with the input held since the last sample, measured on the channel
active at ``t_k`` (plus seeded noise; the shared rows alone in a dead time), and the samples go
through :class:`~switchobs_core.runtime.observer.SwitchedObserver` itself, the code the node
runs: with the sample's innovation held (``hold="innovation"``, the default; every Kalman family
corrects at the sample) or the sample itself held (``hold="measurement"``, LMI gains). With
innovation hold (and the Kalman families) the observer keeps its rounding-aware exact bound,
and the plant is kept in extended precision so that the error column is the computed
estimate's true error; with measurement hold the plant is in double precision and the
observer's exact bound is the exact-arithmetic error-to-error part.

Error transition with sampled outputs. With innovation hold one step maps the error by
``E = e^{A dt} - Gamma_A L C``, independent of the plant. With measurement hold, ``u = 0``
and no noise, one sample step ``dt`` with gain ``L`` maps ``(x, x_tilde)`` by

.. math::

    x^+ = e^{A dt} x, \\qquad
    \\tilde x^+ = \\Phi \\tilde x + (\\Phi + \\Gamma L C - e^{A dt}) x,

(``Phi, Gamma`` the ZOH pair of ``M = A - L C``): the held sample adds a term driven by
the plant state, of order ``dt^2``. :func:`sampled_error_transition` returns the two
blocks ``(Phi_ee, Phi_ex)`` of the product over the steps, so
``x_tilde(t) = Phi_ee x_tilde(0) + Phi_ex x(0)`` exactly; a measurement-hold simulation
carries them along the run as its ``hold_bound``.

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
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..bounds.envelope import Segment, envelope_z, schedule_segments
from ..bounds.envelope import alpha as _alpha
from ..exceptions import InvalidArgument
from ..families import family_of_table
from ..model.schedule import PeriodicSchedule, RandomSchedule, SequenceSchedule, common_rows
from ..numerics.propagation import zoh_pair
from ..numerics.rounding import gamma
from ..ranges import fmt_bytes
from ..runtime.observer import SwitchedObserver
from ..validation import as_matrix
from .continuous import continuous_outputs
from .plant import Plant, input_at
from .progress import progress_bar
from .result import SimulationResult, paper_gains

__all__ = [
    "MAX_RESULT_BYTES",
    "simulate",
    "sampled_error_transition",
    "designs_for",
]


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


def _cycle_end_at(segments: Sequence[Segment], N: int, t_end: float) -> list[float]:
    """``[t_end]`` when the last cycle ends exactly at ``t_end`` (its last channel's residence
    ends there, so the next cycle's channel 1 would start at ``t_end``, outside the run), else
    ``[]``: a run of whole cycles reports every one of them (tolerance 1e-9 relative)."""
    last = segments[-1] if segments else None
    if last is not None and last.channel == N and abs(last.t1 - t_end) <= 1e-9 * max(1.0, abs(t_end)):
        return [float(t_end)]
    return []


class _HeldTransition:
    """The blocks ``(Phi_ee, Phi_ex)`` of the sampled observer's exact error transition with the
    sample held (``u = 0``, no noise; module docstring), one step at a time; a step's matrices are
    cached under its ``key`` when one is given."""

    def __init__(self, A: np.ndarray, C: Sequence[np.ndarray]) -> None:
        n = A.shape[0]
        self.A, self.C = A, C
        self.ee, self.ex, self.xx = np.eye(n), np.zeros((n, n)), np.eye(n)
        self._steps: dict = {}

    def step(self, dt: float, channel: int, L: np.ndarray, key: Any = None) -> None:
        """Multiply in one step of length ``dt`` with ``channel`` (1-based) and its gain ``L`` held."""
        s = None if key is None else self._steps.get(key)
        if s is None:
            Ci = self.C[channel - 1]
            Phi, Gamma = zoh_pair(self.A - L @ Ci, dt)
            F = expm(self.A * dt)
            s = (Phi, Phi + Gamma @ L @ Ci - F, F)
            if key is not None:
                self._steps[key] = s
        Phi, D, F = s
        self.ee, self.ex, self.xx = Phi @ self.ee, Phi @ self.ex + D @ self.xx, F @ self.xx


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
    tr = _HeldTransition(A, C)
    for k, step in enumerate(steps):
        try:
            dt, ch, L = step
        except (TypeError, ValueError):
            raise InvalidArgument(f"steps[{k}] must be (dt, channel, L); got {step!r}") from None
        if not (isinstance(ch, (int, np.integer)) and 1 <= ch <= len(C)):
            raise InvalidArgument(f"steps[{k}]: channel must be in 1..{len(C)}; got {ch!r}")
        tr.step(dt, ch, as_matrix(L, f"steps[{k}] L", rows=n, cols=C[ch - 1].shape[0]))
    return tr.ee, tr.ex


MAX_RESULT_BYTES = 2 * 2**30
"""Largest result (all output arrays) :func:`simulate` builds; longer runs are refused up front."""


def simulate(system: Any, table: Any, schedule: Any, x0: Any, xhat0: Any, t_end: float, *,
             rate: float | None = None, noise_std: float = 0.0, process_noise: Any = 0.0,
             seed: int = 0, mode: str | None = None, dt_out: float = 0.01,
             u: Any = None, e0: float | None = None, t0: float | None = None,
             hold: str = "innovation", noise_max: Any = None, progress: bool | None = False,
             bound: str = "ellipsoid") -> SimulationResult:
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
        Input, held (ZOH) from each sample (continuous outputs: each output grid point) to the
        next at its value there, by plant and observer alike.
    e0 : float, optional
        Initial error bound for the envelopes and the exact bound (default
        ``||xhat0 - x0||``).
    t0 : float, optional
        Start time (default ``schedule.t0``).
    hold : {"innovation", "measurement"}
        Sampled outputs with LMI gains: what the observer holds between samples (module
        docstring); the Kalman families correct at the sample and hold nothing.
    noise_max : float or (N,) sequence, optional
        A declared bound on the measurement noise (per row, one value or one per channel):
        the noise draws are clipped to it and the result carries the observer's
        ``noise_bound`` (innovation hold and the Kalman families).
    progress : bool or None
        A progress bar on stderr over the simulated samples (None: on a terminal only; default off).
    bound : {"ellipsoid", "phase"}
        The form of the observer's rigorous bounds (sampled outputs;
        :mod:`switchobs_core.runtime.bound_option`: ``"phase"`` for a Kalman table, cheaper and looser).

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
    if rate is not None or not paper_gains(family_of_table(table)):
        return _sampled(system, table, schedule, x0, xhat0, t0, t_end, rate, noise_std, process_noise, seed, mode, u,
                        e0, noise_max, hold, progress, bound)
    mode, designs = designs_for(table, schedule, mode)
    segments = schedule_segments(schedule, designs, t_end)
    T_o = [system.decomposition(i + 1).T_o for i in range(N)]
    try:
        alpha_ = float(system.alpha)
    except AttributeError:
        alpha_ = _alpha(T_o)
    run = continuous_outputs(A, B, C, segments, x0, xhat0, t0, t_end, dt_out, u, process_noise, seed, e0,
                             progress=progress)
    t = run.t
    err = run.x_hat - run.x
    z = envelope_z(t, segments, e0)
    xo = np.stack([np.linalg.norm(err @ Ti, axis=1) for Ti in T_o])
    sw = np.array([s.t0 for s in segments if s.starts_residence])
    ends = np.array([s.t0 for s in segments if s.channel == 1 and s.starts_residence and s.t0 > segments[0].t0]
                    + _cycle_end_at(segments, N, t_end))
    return SimulationResult(t=t, x=run.x, x_hat=run.x_hat, error=err, channel=run.channel, z=z,
                            paper_bound=alpha_ * z.sum(axis=0), exact_bound=run.exact_bound, xo_norms=xo,
                            switching_times=sw, cycle_ends=ends, alpha=alpha_, e0=e0, rate=None,
                            segments=segments)


def _sampled(system, table, schedule, x0, xhat0, t0, t_end, rate, noise_std, process_noise, seed, mode, u, e0,
             noise_max, hold, progress=False, bound="ellipsoid") -> SimulationResult:
    """Sampled outputs through :class:`SwitchedObserver` itself, the code the node runs (module docstring).

    With innovation hold and the Kalman families the plant is :class:`Plant` with ``extended=True``
    (the reference of :mod:`switchobs_core.numerics.rounding`): ``x`` is its state rounded once to
    double, and ``error`` is ``x_hat - x`` taken in extended precision, so the exact bound (which
    includes the observer's rounding) is checked against the error of the computed estimate, not
    against the simulator's own rounding. With measurement hold the plant is in double precision
    and the run carries the blocks of :func:`sampled_error_transition` for ``hold_bound``: each
    step holds the gain of the observer's design for the previous sample's channel (none while
    the schedule is blind). The paper's envelopes are the observer's (LMI gains; for the Kalman
    gains ``z`` and ``paper_bound`` are :data:`~switchobs_core.runtime.observer.NOT_APPLICABLE`).
    """
    if rate is None:
        raise InvalidArgument("a kalman gain table is a sampled filter: pass --rate HZ")
    if mode is None:
        mode = ("robust" if isinstance(schedule, RandomSchedule) else
                "periodic" if isinstance(schedule, PeriodicSchedule) else "sequence")
    cycles = None if mode == "robust" else list(schedule.cycles)
    if not paper_gains(family_of_table(table)):
        hold = "innovation"         # a Kalman family corrects at the sample: there is nothing to hold
    held = hold == "measurement"
    obs = SwitchedObserver(system, table, mode, cycles, x0=xhat0, t0=t0, e0=e0, noise_max=noise_max, hold=hold,
                           bound=bound)
    plant = Plant(system, x0, seed=seed, process_noise=process_noise, t0=t0, extended=not held)
    vmax = None if noise_max is None else np.broadcast_to(np.asarray(noise_max, dtype=float), (system.N,))
    K = int(math.floor((t_end - t0) * rate + 1e-9))
    n, N = system.n, system.N
    t = t0 + np.arange(K + 1) / rate
    X, Xh, err = np.empty((K + 1, n)), np.empty((K + 1, n)), np.empty((K + 1, n))
    ch, exact = np.empty(K + 1, dtype=int), np.empty(K + 1)
    noise_b = None if noise_max is None else np.empty(K + 1)
    z, paper = np.empty((N, K + 1)), np.empty(K + 1)
    hold_b, tr, x0n, gain = None, None, 0.0, None
    if held:
        hold_b, x0n = np.empty(K + 1), float(np.linalg.norm(x0))
        tr = _HeldTransition(plant.A, plant.C)
    ys = []
    blind_rows = None
    if any(c.dead_time for c in getattr(schedule, "cycles", [])):
        blind_rows = common_rows(system.C)
        if not blind_rows:
            raise InvalidArgument("a dead time with channels that share no output row: nothing is measured while "
                                  "blind, which simulate does not model; use channels with common rows")
    u_held = None
    for k, tk in enumerate(progress_bar(t, progress, "sample")):
        uk = input_at(u, tk, plant.B.shape[1])
        X[k] = plant.advance(tk, u_held)
        u_held = uk
        ch[k] = c = schedule.channel_at(tk)
        y = plant.measure(c, noise_std, noise_max=None if vmax is None else float(vmax[c - 1]))
        rows = blind_rows if blind_rows is not None and schedule.blind_at(tk) else None
        if rows is not None:            # the dead time after a switch: only the shared rows
            y = y[list(rows)]
        ys.append(y)
        if tr is not None and k > 0:    # the step into this sample held the previous sample's gain
            d, gc, blind = gain
            L = np.asarray(d.L[gc - 1], dtype=float)
            tr.step(tk - t[k - 1], gc, np.zeros_like(L) if blind else L, (id(d), gc, blind, tk - t[k - 1]))
        Xh[k] = xh = obs.update(tk, c, y, u=uk, rows=rows)
        err[k] = xh - X[k] if held else np.asarray(xh - plant.x_extended, dtype=float)
        env = obs.envelope()
        exact[k], z[:, k], paper[k] = env.exact_bound, env.z, env.paper_bound
        if noise_b is not None:
            noise_b[k] = env.noise_bound
        if tr is not None:
            gain = (obs.current_design, c, rows is not None)
            hold_b[k] = np.linalg.norm(tr.ee, 2) * e0 + np.linalg.norm(tr.ex, 2) * x0n
    T_o = [system.decomposition(i + 1).T_o for i in range(N)]
    sw = t[np.r_[True, ch[1:] != ch[:-1]]]
    ends = t[1:][(ch[1:] == 1) & (ch[:-1] != 1)]
    return SimulationResult(t=t, x=X, x_hat=Xh, error=err, channel=ch, z=z, paper_bound=paper, exact_bound=exact,
                            xo_norms=np.stack([np.linalg.norm(err @ Ti, axis=1) for Ti in T_o]),
                            switching_times=sw, cycle_ends=ends, alpha=float(system.alpha), e0=e0, rate=rate,
                            family=obs.family, y=ys, noise_bound=noise_b, hold_bound=hold_b,
                            noisy=bool(noise_std) or bool(np.any(plant.Qc)))
