"""Offline periodic Kalman gains for a known schedule (the ``kalman`` gain family; beyond the paper).

For a schedule known in advance (one cycle repeated, or a list of cycles repeated: the paper's
periodic and nonperiodic cases, e:switching_instants, e:tau_k) and a nominal sample rate f,
the Riccati recursion of :mod:`switchobs_core.design.riccati` depends only on the sample pattern, ``Q_c``, ``R``
and ``P0``, not on the data. So the gains are computed here once and looked up by sample
phase at run time: the cost of a table lookup, the accuracy of a Kalman filter.

Sample pattern. Samples are at ``t_k = k / f`` from the start of the cycle sequence, on the
channel ``schedule.channel_at(t_k)`` (the rule of the simulator and the camera simulator).
The pattern repeats after ``K`` samples when ``K = m T f`` is an integer (within 1e-9) for
the super-cycle length ``T = sum tau`` and the smallest ``m`` in ``1..max_repeat``;
otherwise :func:`design_kalman` raises (pick a rate with ``T f`` rational of small
denominator). A sample within 1 ns of a switching instant is a *tie*: in floating point
``channel_at`` gives it either channel from one period to the next; the design uses the
channel of the first period and lists the tie phases, and
:meth:`~switchobs_core.table.kalman.KalmanDesign.gain` serves a sample whose channel differs from
its phase's with a gain from the stored prior.

Dead time. A cycle with a dead time ``d`` (:mod:`switchobs_core.model.schedule`) makes the samples in the first
``d`` seconds of every residence *blind*: they measure only the rows every channel shares, and
their step uses those rows (:mod:`switchobs_core.table.kalman`).

Detectability. Before solving, the period pair is checked: with ``Phi = e^{A/f}``, every
eigenvalue of the monodromy ``Phi^K`` with ``|lambda| >= 1`` must be seen by some sample of the
period (PBH on the eigenvectors, with the growth over the period factored out so that the test
stays right for large n: :mod:`switchobs_core.model.detectability`; d:obs_detect, e:detectability_condition in
discrete time). The Riccati solver checks it once more on its result: the closed-loop error map
of the period must be a contraction (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`).

Precision. A schedule that leaves a channel unseen so long that the periodic covariance would
span more than double precision resolves is refused with one line
(:class:`~switchobs_core.exceptions.PrecisionError`, :mod:`switchobs_core.design.precision`):
before the doubling from the growth of the directions only that channel sees over its longest
unseen stretch, after it from the span of the priors themselves. A table is never written for a
filter that no float64 filter can run.

Process noise and a declared disturbance. ``Q_c`` is the spectral density of continuous-time white
noise, discretised exactly per sample step (van Loan, ``Q_d = int_0^dt e^{A s} Q_c e^{A's} ds``). A
system that declares a bounded disturbance ``x' = A x + B_w w``, ``|w_j| <= max_j``
(:mod:`switchobs_core.model.disturbance`) and no process noise of its own gets
``Q_c = B_w diag(max^2) B_w'`` (:func:`switchobs_core.model.scenarios.load_noise`): the same ``B_w``
read as a spectral density with ``max_j^2`` per input (a white acceleration of intensity
``0.04 m^2/s^3`` for ``max = 0.2 m/s^2``), not the discretised equivalent. It tunes the gains only;
the guarantee under the disturbance is the noise bound's, whatever the gains.

The result is a :class:`~switchobs_core.table.kalman.KalmanDesign` (the stored data and its lookup by
sample phase, :mod:`switchobs_core.table.kalman`), which a gain table holds
(:func:`~switchobs_core.table.gains.kalman_table`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument, KalmanDesignError, UndetectableSchedule
from ..model.detectability import undetectable_modes
from ..model.noise import NoiseModel, default_noise
from ..model.schedule import Cycle, PeriodicSchedule, Schedule, SequenceSchedule, check_cycle_horizon
from ..ranges import check_size
from ..table.kalman import KalmanDesign, KalmanPhase, SamplePattern
from .doubling import solve_periodic_riccati, startup_run
from .precision import check_covariance, check_unseen, cycles_label, pattern_stretches
from .progress import StageBar
from .riccati import Step, discretize, rel_change

__all__ = [
    "sample_pattern",
    "check_detectable",
    "design_kalman",
    "TIE_TOL",
    "STARTUP_BUDGET_BYTES",
    "startup_cap",
    "design_bytes",
    "design_pattern",
]

#: A sample closer than this (s) to a switching instant is a tie (module docstring).
TIE_TOL = 1e-9
_PERIOD_TOL = 1e-9
#: Memory the stored start-up priors may take by default (bytes): 256 MiB, 1.2 periods of the
#: 32-agent camera model at 50 Hz (its periodic priors alone take 223 MB).
STARTUP_BUDGET_BYTES = 256 * 1024 * 1024


def startup_cap(K: int, n: int) -> int:
    """Most start-up samples :func:`design_kalman` stores by default for a period of ``K`` samples
    of an n-state system: 64 periods, at most what :data:`STARTUP_BUDGET_BYTES` of priors hold,
    but at least one period."""
    return min(64 * K, max(K, STARTUP_BUDGET_BYTES // (8 * n * n)))


def design_bytes(n: int, p: int, K: int, startup: int) -> int:
    """Memory (bytes) a Kalman design of a ``K``-sample period and ``startup`` stored start-up samples
    allocates, with the table written from it (n states, at most p rows per sample).

    Per stored sample (``K + startup`` of them): the prior and the gain (``8 (n^2 + n p)``,
    :class:`KalmanPhase`), their copy in the binary table (``8 (n (n + 1) / 2 + 2 n p)``: the
    packed prior, the gain flattened and concatenated, :func:`~switchobs_core.table.container.encode`)
    and 1 KiB of Python objects (step, phase, rows). Fixed: the doubling's work space, O(n^2) and
    nothing per iteration or per sample beyond the priors it returns (:mod:`switchobs_core.design.doubling`; 64 n x n
    matrices are counted), and numpy's write buffer of the table file (the largest array, at most
    16 MiB).
    For the 32-agent camera model at 50 Hz (n = 132, K = 1600, a start-up of 1925 samples capped
    by :data:`STARTUP_BUDGET_BYTES`): 0.75 GiB, under the 1 GiB budget (measured peak RSS of
    ``switchobs design``: 0.95 GiB, with the interpreter, numpy, scipy and cvxpy).
    """
    per_sample = 8 * (n * n + n * p) + 8 * (n * (n + 1) // 2 + 2 * n * p) + 1024
    write_buffer = min(16 * 2**20, 8 * max(K, startup) * (n * (n + 1) // 2))
    return (K + startup) * per_sample + 64 * 8 * n * n + write_buffer


def _schedule(cycles: Sequence[Cycle]) -> Schedule:
    return PeriodicSchedule(cycles[0]) if len(cycles) == 1 else SequenceSchedule(cycles)


def _as_cycles(cycles: Cycle | Sequence[Cycle]) -> tuple[Cycle, ...]:
    if isinstance(cycles, Cycle):
        return (cycles,)
    try:
        out = tuple(cycles)
    except TypeError:
        raise InvalidArgument(f"cycles must be a Cycle or a list of Cycles; got {cycles!r}") from None
    if not out or not all(isinstance(c, Cycle) for c in out):
        raise InvalidArgument(
            f"cycles must be a non-empty list of Cycles (e.g. [Cycle.from_ts(2, 0.6)]); got {cycles!r}"
        )
    return out


def sample_pattern(cycles: Cycle | Sequence[Cycle], rate: float, *, max_repeat: int = 64,
                   memory: Callable[[int], int] | None = None) -> SamplePattern:
    """The channel of every sample over one period (module docstring).

    ``memory(K)``: bytes the caller will allocate for a period of K samples (default: 64 per
    sample, the pattern itself); checked against :data:`~switchobs_core.ranges.MEMORY_BUDGET_BYTES`
    before anything is allocated.

    Raises
    ------
    KalmanDesignError
        ``m T f`` is not an integer for any ``m <= max_repeat``.
    InvalidArgument
        The period holds more samples than the memory budget allows.
    """
    cyc = _as_cycles(cycles)
    if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating)) or not (
        math.isfinite(rate) and rate > 0
    ):
        raise InvalidArgument(f"rate must be a finite number > 0 (Hz); got {rate!r}")
    rate = float(rate)
    T = sum(c.tau for c in cyc)
    for m in range(1, int(max_repeat) + 1):
        x = m * T * rate
        if abs(x - round(x)) <= _PERIOD_TOL * max(1.0, x):
            K = int(round(x))
            break
    else:
        raise KalmanDesignError(
            f"the cycle sequence (length T = {T:g} s) at {rate:g} Hz has T f = {T * rate:.9g} samples, not a whole "
            f"number even over {max_repeat} repetitions; choose a rate with T f an integer "
            f"(e.g. {max(1, round(T * rate))}/T Hz)"
        )
    check_size(K, 64 if memory is None else memory(K) / K, f"{K:.3g} samples per period ({T * m:g} s at {rate:g} Hz)",
               "lower the rate or shorten the cycles")
    sch = _schedule(cyc)
    ts = np.arange(K) / rate
    channels = tuple(int(sch.channel_at(float(t))) for t in ts)
    sw = sch.switching_instants(m * T + TIE_TOL)
    ties = tuple(k for k, t in enumerate(ts) if np.min(np.abs(sw - t)) <= TIE_TOL and k > 0)
    blind = tuple(bool(sch.blind_at(float(t))) for t in ts) if any(c.dead_time for c in cyc) else ()
    return SamplePattern(rate, cyc, m, channels, ties, blind)


def check_detectable(system: Any, pattern: SamplePattern) -> None:
    """Raise :class:`UndetectableSchedule` unless the sampled periodic pair is detectable (module docstring).

    The message names every undetectable mode: its growth rate and its direction in the state labels.
    """
    A = np.asarray(system.A, dtype=float)
    n, K = A.shape[0], pattern.K
    H = []
    for k in range(K):
        C = system.C[pattern.channels[k] - 1]
        r = pattern.rows(k, system)
        H.append(C if r is None else C[list(r)])
    bad = undetectable_modes(A, H, 1.0 / pattern.rate)
    if not bad:
        return
    labels = getattr(system, "state_labels", tuple(f"x{j}" for j in range(n)))
    dirs = []
    for m in bad:
        v = m.v
        dirs.append(" ".join(f"{v[i]:+.3g}*{labels[i]}" for i in np.argsort(-np.abs(v))[:4] if abs(v[i]) > 1e-6))
    seen = {pattern.channels[k] for k in range(K) if not pattern.is_blind(k)}
    unseen = sorted(set(range(1, system.N + 1)) - seen)
    hint = f" Channel(s) {unseen} get no sample in the period" + (" outside the dead time." if pattern.blind else
                                                                   ".") if unseen else ""
    rates = ", ".join(f"{m.lam.real:.4g}" for m in bad)
    raise UndetectableSchedule(
        f"schedule {', '.join(c.label() for c in pattern.cycles)} at {pattern.rate:g} Hz is not detectable: "
        f"{len(bad)} mode(s) of the period transition with |lambda| >= 1 (growth rates {rates} 1/s) are never "
        f"observed. Undetectable direction(s): {'; '.join(dirs)}.{hint} Raise the rate or lengthen the short "
        "active times."
    )


def design_pattern(system: Any, cycles: Cycle | Sequence[Cycle], rate: float, *, max_repeat: int = 64,
                   max_startup: int | None = None) -> SamplePattern:
    """The sample pattern of a Kalman design (step 1 of :func:`design_kalman`), refused with one line
    (:class:`~switchobs_core.exceptions.InvalidArgument`) when the design would need more than the
    memory budget (:func:`design_bytes`, start-up :func:`startup_cap` or ``max_startup`` samples)."""
    n, p = int(system.n), max(system.p)

    def memory(K: int) -> int:
        return design_bytes(n, p, K, startup_cap(K, n) if max_startup is None else max(0, int(max_startup)))

    return sample_pattern(cycles, rate, max_repeat=max_repeat, memory=memory)


def design_kalman(
    system: Any,
    cycles: Cycle | Sequence[Cycle],
    rate: float,
    noise: NoiseModel | None = None,
    *,
    rtol: float = 1e-12,
    startup_rtol: float = 1e-11,
    max_startup: int | None = None,
    max_repeat: int = 64,
    progress: bool | None = False,
) -> KalmanDesign:
    """Offline periodic Kalman gains for ``cycles`` (one cycle, or a sequence repeated) at ``rate`` Hz.

    ``design = design_kalman(system, Cycle.from_ts(2.0, 0.6), 50.0, default_noise(system))``

    Steps: 1. sample pattern over one period; 2. detectability of the sampled periodic pair, and
    the growth of each channel's unseen directions within double precision;
    3. periodic Riccati solution by doubling (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`,
    residual ``<= rtol``; its covariance's span within double precision), and the start-up segment
    from ``P0`` (``startup_rtol``, at most ``max_startup`` samples: default 64 periods, at most what
    :data:`STARTUP_BUDGET_BYTES` of priors hold but at least one period:
    :func:`~switchobs_core.design.doubling.startup_run`);
    4. the period's error transition. ``progress``: a bar over these steps on stderr (None: on a
    terminal only; default off).

    Raises
    ------
    KalmanDesignError
        No whole number of samples per period (see :func:`sample_pattern`).
    UndetectableSchedule
        Some unstable mode is never observed by the sampled schedule.
    PrecisionError
        The design is beyond double precision: a channel unseen so long that the periodic
        covariance would span more than :data:`~switchobs_core.design.precision.PRECISION_RANGE`
        (checked before the doubling from the growth of what only that channel sees, and after it
        on the priors; :mod:`switchobs_core.design.precision`).
    RiccatiError
        The doubling does not settle, or its solution is not stabilising.
    """
    noise = default_noise(system) if noise is None else noise
    if not isinstance(noise, NoiseModel):
        raise InvalidArgument(f"noise must be a NoiseModel; got {type(noise).__name__}")
    noise.check_system(system)
    bar = StageBar(("sample pattern", "detectability", "periodic Riccati (doubling)", "start-up from P0",
                    "error transition"), progress)
    # 1. sample pattern (of cycles short enough to be represented, see check_cycle_horizon)
    for c in [cycles] if isinstance(cycles, Cycle) else list(cycles):
        if isinstance(c, Cycle):
            check_cycle_horizon(system.A, c)
    pattern = design_pattern(system, cycles, rate, max_repeat=max_repeat, max_startup=max_startup)
    # 2. detectability, and the dynamic range double precision must carry (before the doubling)
    bar.next()
    check_detectable(system, pattern)
    what = f"the Kalman design of {cycles_label(pattern.cycles)} at {pattern.rate:g} Hz"
    stretches = pattern_stretches(pattern.channels, pattern.blind, pattern.rate, system.N)
    check_unseen(system, stretches, power=2, what=what)
    # 3. periodic Riccati solution (its covariance within double precision) and start-up
    A = np.asarray(system.A, dtype=float)
    dt = 1.0 / pattern.rate
    Phi, _, Qd = discretize(A, np.asarray(system.B, dtype=float), noise.Q_c, dt)
    K = pattern.K
    rows = [pattern.rows(k, system) for k in range(K)]
    steps = [Step(Phi, Qd, system.C[c - 1] if r is None else system.C[c - 1][list(r)], noise.R(c, r))
             for c, r in zip(pattern.channels, rows)]
    bar.next()
    sol = solve_periodic_riccati(steps, rtol=rtol)
    check_covariance(system, sol.P_prior, stretches, what=what)
    bar.next()
    if max_startup is None:
        max_startup = startup_cap(K, A.shape[0])
    # max_startup = 0: no start-up segment (its distance: P0 from the periodic prior of phase 0)
    su_P, su_K, su_change = [], [], rel_change(noise.P0, sol.P_prior[0])
    if max_startup > 0:
        su_P, su_K, su_change = startup_run(steps, sol.P_prior, noise.P0, rtol=startup_rtol, max_samples=max_startup)
    # the gains in C order, as a loaded table holds them (a solve's transpose is in Fortran order): the
    # bound sums ||D^-1 K||_F in memory order (numerics.rounding.fro_norm), so a designed table and the
    # same table loaded would publish bounds an ulp apart
    c = np.ascontiguousarray
    periodic = [KalmanPhase(pattern.channels[k], dt, sol.P_prior[k], c(sol.K[k]), rows[k]) for k in range(K)]
    startup = [KalmanPhase(pattern.channels[k % K], 0.0 if k == 0 else dt, P, c(Kk), rows[k % K])
               for k, (P, Kk) in enumerate(zip(su_P, su_K))]
    # 4. error transition over one period: e+_{k+1} = (I - K H) Phi e+_k, phases 1..K-1 then 0
    bar.next()
    M = sol.transition
    bar.close()
    return KalmanDesign(system, noise, pattern, periodic, startup, sol.periods, sol.change, M, sol.rho,
                        float(np.linalg.norm(M, 2)), su_change)
