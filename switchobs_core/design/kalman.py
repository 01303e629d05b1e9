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
channel of the first period and lists the tie phases, and :meth:`KalmanDesign.gain` serves a
sample whose channel differs from its phase's with a gain from the stored prior.

Dead time. A cycle with a dead time ``d`` (:mod:`switchobs_core.model.schedule`) makes the samples in the first
``d`` seconds of every residence *blind*: they measure only the rows every channel shares
(:func:`~switchobs_core.model.schedule.common_rows`: the camera's own pose), and their stored step
uses ``H = C_rho[common rows]`` (``KalmanPhase.rows``). ``pattern.blind[k]`` says which.

Detectability. Before solving, the period pair is checked: with ``Phi = e^{A/f}``, every
eigenvalue of the monodromy ``Phi^K`` with ``|lambda| >= 1`` must be seen by some sample of the
period (PBH on the eigenvectors, with the growth over the period factored out so that the test
stays right for large n: :mod:`switchobs_core.model.detectability`; d:obs_detect, e:detectability_condition in
discrete time). The Riccati solver checks it once more on its result: the closed-loop error map
of the period must be a contraction (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`).

Lookup. :meth:`KalmanDesign.phase_at` maps the time since the sequence start to the nearest
sample (stamp jitter), start-up first (the recursion from ``P0`` until it meets the periodic
solution), then periodic. A sample with only some rows (a dropped target pose) gets
``K_r = P^- H_r' (H_r P^- H_r' + R_r)^{-1}`` from the stored prior of its phase. The
table-lookup filter does not track the covariance: at the next sample it uses the stored
prior of that phase again, as if the full sample had arrived (after a partial sample the true
covariance is a little larger; the loss is measured in the tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import DesignError, InvalidArgument
from ..model.detectability import undetectable_modes
from ..model.noise import NoiseModel, default_noise
from ..model.schedule import Cycle, PeriodicSchedule, Schedule, SequenceSchedule, check_cycle_horizon, common_rows
from ..ranges import check_size
from ..table.container import packed_size, unpack_symmetric
from .doubling import solve_periodic_riccati, startup_run
from .riccati import (
    DiscretizationCache,
    Step,
    correct_state,
    discretize,
    gain,
    joseph,
    rel_change,
)

__all__ = [
    "KalmanDesignError",
    "UndetectableSchedule",
    "SamplePattern",
    "sample_pattern",
    "check_detectable",
    "KalmanPhase",
    "Phase",
    "KalmanDesign",
    "design_kalman",
    "TableKalman",
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


class KalmanDesignError(DesignError):
    """The offline Kalman design could not be carried out (sample pattern, convergence)."""


class UndetectableSchedule(KalmanDesignError):
    """The sampled periodic pair is not detectable: some unstable mode is never seen."""


@dataclass(frozen=True)
class SamplePattern:
    """One period of samples: ``channel[k]`` of sample ``k`` at ``t_k = k / rate``, ``k < K``;
    ``blind[k]`` when it falls in a dead time (module docstring; empty: none is)."""

    rate: float
    cycles: tuple[Cycle, ...]
    repeat: int
    channels: tuple[int, ...]
    ties: tuple[int, ...]
    blind: tuple[bool, ...] = ()

    def is_blind(self, k: int) -> bool:
        """Whether sample ``k`` of the period is blind."""
        return bool(self.blind) and self.blind[k]

    def rows(self, k: int, system: Any) -> tuple[int, ...] | None:
        """Rows of ``C_channel`` measured at sample ``k``: None (all) or the common rows when blind."""
        return common_rows(system.C) if self.is_blind(k) else None

    @property
    def dead_time(self) -> float:
        """The dead time of the cycles (0 without one)."""
        return max(c.dead_time for c in self.cycles)

    @property
    def K(self) -> int:
        """Samples per period."""
        return len(self.channels)

    @property
    def period(self) -> float:
        """Period in seconds (``repeat`` super-cycles)."""
        return self.repeat * sum(c.tau for c in self.cycles)


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


@dataclass(frozen=True, eq=False)
class KalmanPhase:
    """One stored sample: ``channel`` (1-based), ``dt`` since the previous sample, prior ``P^-``, gain
    ``K``, and the ``rows`` of ``C_channel`` it measures (None: all; the common rows when blind).

    The prior is given (``P_stored``) either as the (n, n) matrix or as its packed upper triangle
    (what a binary table file holds, :mod:`switchobs_core.table.container`); :attr:`P_prior` is the matrix, unpacked
    on first use (the same doubles), so loading a large table does not unpack every phase."""

    channel: int
    dt: float
    P_stored: np.ndarray
    K: np.ndarray
    rows: tuple[int, ...] | None = None

    @property
    def P_prior(self) -> np.ndarray:
        """The prior covariance ``P^-`` of this sample (n x n)."""
        P = self.P_stored
        if P.ndim == 1:
            P = unpack_symmetric(P, self.K.shape[0])
            object.__setattr__(self, "P_stored", P)
        return P

    def has_rows(self, rows: Sequence[int] | None) -> bool:
        """Whether a sample with ``rows`` (None: all) measures exactly this phase's rows."""
        if self.rows is None:
            return rows is None or (len(rows) == self.K.shape[1] and list(rows) == list(range(self.K.shape[1])))
        return rows is not None and tuple(rows) == self.rows


@dataclass(frozen=True)
class Phase:
    """A looked-up sample: ``startup`` segment or periodic, ``index`` into it, sample number ``k``,
    and ``offset`` = stamp minus the nominal sample time (s)."""

    startup: bool
    index: int
    k: int
    offset: float


def _phases_to_dict(ph: Sequence[KalmanPhase], arrays: bool = False) -> dict[str, list]:
    out = {
        "channel": [p.channel for p in ph],
        "dt": [p.dt for p in ph],
        "P_prior": [p.P_prior if arrays else p.P_prior.tolist() for p in ph],
        "K": [p.K if arrays else p.K.tolist() for p in ph],
    }
    if any(p.rows is not None for p in ph):     # only with a dead time: tables without one keep their bytes
        out["rows"] = [None if p.rows is None else list(p.rows) for p in ph]
    return out


def _phases_from_dict(d: dict[str, list]) -> list[KalmanPhase]:
    try:
        rows = d.get("rows") or [None] * len(d["channel"])
        out = []
        for c, dt, P, K, r in zip(d["channel"], d["dt"], d["P_prior"], d["K"], rows, strict=True):
            P = np.asarray(P, dtype=float)
            n = P.shape[0] if P.ndim == 2 else packed_size(P.size)
            out.append(KalmanPhase(int(c), float(dt), P, np.asarray(K, dtype=float).reshape(n, -1),
                                   None if r is None else tuple(int(i) for i in r)))
        return out
    except (KeyError, TypeError, ValueError) as err:
        raise KalmanDesignError(f"stored Kalman phases are malformed ({err})") from None


@dataclass(frozen=True, eq=False)
class KalmanDesign:
    """Offline periodic Kalman gains of one (super-)cycle at a nominal rate.

    Attributes
    ----------
    system : LTISystem
    noise : NoiseModel
    pattern : SamplePattern
        Rate, cycles, repeat count, channel of each sample, tie phases.
    periodic : list of KalmanPhase
        K phases of the periodic solution (sample k >= len(startup) uses ``periodic[k % K]``).
    startup : list of KalmanPhase
        Samples 0..S-1 of the recursion from P0, before it meets the periodic solution.
    periods : int
        Doublings of the period map plus sweeps (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`).
    change : float
        Relative change of the prior of phase 0 over the last sweep (the residual).
    error_transition : (n, n) ndarray
        ``prod_k (I - K_k H_k) Phi`` over one period, from the posterior of phase 0 to that of
        the next period's phase 0 (noise-free error map, e:error_dynamics sampled).
    rho, norm : float
        Its spectral radius and 2-norm.
    startup_change : float
        Distance (:func:`~switchobs_core.design.riccati.rel_change`) of the last stored start-up period
        from the periodic solution: ``<= startup_rtol`` unless the start-up was capped
        (``max_startup``; the periodic gains serve from there).
    """

    system: Any
    noise: NoiseModel
    pattern: SamplePattern
    periodic: list[KalmanPhase]
    startup: list[KalmanPhase]
    periods: int
    change: float
    error_transition: np.ndarray
    rho: float
    norm: float
    startup_change: float = 0.0
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def rate(self) -> float:
        """Nominal sample rate (Hz)."""
        return self.pattern.rate

    @property
    def cycles(self) -> tuple[Cycle, ...]:
        """The cycle sequence (one period of the schedule)."""
        return self.pattern.cycles

    def phase_at(self, t: float, *, max_jitter: float = 0.25) -> Phase:
        """The nearest sample to time ``t`` (s since the sequence start), start-up first.

        Raises InvalidArgument for ``t < 0`` (beyond half a sample) or a stamp farther than
        ``max_jitter`` sample periods from the nominal grid.
        """
        t = float(t)
        f = self.pattern.rate
        k = round(t * f)
        if not math.isfinite(t) or k < 0:
            raise InvalidArgument(f"t must be a finite time >= 0 since the cycle sequence started; got {t!r}")
        off = t - k / f
        if abs(off) * f > max_jitter:
            raise InvalidArgument(
                f"t = {t!r} s is {abs(off) * f:.3g} sample periods off the {f:g} Hz grid (max_jitter {max_jitter:g})"
            )
        S = len(self.startup)
        if k < S:
            return Phase(True, k, k, off)
        return Phase(False, k % self.pattern.K, k, off)

    def entry(self, phase: Phase) -> KalmanPhase:
        """The stored sample of ``phase``."""
        return self.startup[phase.index] if phase.startup else self.periodic[phase.index]

    def H(self, channel: int, rows: Sequence[int] | None = None) -> np.ndarray:
        """Rows ``rows`` (0-based, default all) of ``C_channel`` (e:outputs)."""
        C = self.system.C[channel - 1]
        return C if rows is None else C[list(rows)]

    def gain(self, phase: Phase, channel: int | None = None, rows: Sequence[int] | None = None) -> np.ndarray:
        """The gain of a sample at ``phase`` on ``channel`` (default: the phase's) with ``rows``.

        The stored full-row gain when channel and rows are the phase's; otherwise
        ``K_r = P^- H_r' (H_r P^- H_r' + R_r)^{-1}`` from the stored prior (cached).
        """
        e = self.entry(phase)
        ch = e.channel if channel is None else int(channel)
        if channel is None and rows is None:
            rows = e.rows
        if e.has_rows(rows) and (ch == e.channel or e.rows is not None and self._same_H(ch, e.channel, e.rows)):
            return e.K
        key = (phase.startup, phase.index, ch, None if rows is None else tuple(rows))
        K = self._cache.get(key)
        if K is None:
            K = self._cache[key] = gain(e.P_prior, self.H(ch, rows), self.noise.R(ch, rows))
        return K

    def _same_H(self, a: int, b: int, rows: Sequence[int]) -> bool:
        """Whether channels ``a`` and ``b`` measure the same ``rows`` (the common rows of a blind sample)."""
        return np.array_equal(self.H(a, rows), self.H(b, rows))

    def posterior(self, phase: Phase, channel: int | None = None, rows: Sequence[int] | None = None) -> np.ndarray:
        """Covariance after the correction at ``phase`` (Joseph form from the stored prior)."""
        e = self.entry(phase)
        ch = e.channel if channel is None else int(channel)
        if channel is None and rows is None:
            rows = e.rows
        return joseph(e.P_prior, self.gain(phase, ch, rows), self.H(ch, rows), self.noise.R(ch, rows))

    # ------------------------------------------------------------ persistence
    def to_dict(self, *, arrays: bool = False) -> dict[str, Any]:
        """JSON-ready form (plain lists of floats; :meth:`from_dict` restores it exactly); with
        ``arrays`` the matrices stay numpy arrays (no copy: what a gain table holds in memory)."""
        return {
            "family": "kalman",
            "system_fingerprint": self.system.fingerprint(),
            "noise": self.noise.to_dict(),
            "rate": self.pattern.rate,
            "cycles": [list(c.h) for c in self.pattern.cycles],
            **({"dead_time": self.pattern.dead_time} if self.pattern.dead_time else {}),
            "repeat": self.pattern.repeat,
            "ties": list(self.pattern.ties),
            "periodic": _phases_to_dict(self.periodic, arrays),
            "startup": _phases_to_dict(self.startup, arrays),
            "periods": self.periods,
            "change": self.change,
            "error_transition": self.error_transition if arrays else self.error_transition.tolist(),
            "rho": self.rho,
            "norm": self.norm,
            "startup_change": self.startup_change,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], system: Any) -> KalmanDesign:
        """Inverse of :meth:`to_dict`; ``system`` must have the stored fingerprint."""
        try:
            if d.get("family") != "kalman":
                raise KalmanDesignError(f"not a kalman design (family {d.get('family')!r})")
            if d["system_fingerprint"] != system.fingerprint():
                raise KalmanDesignError("the stored Kalman design was made for another system (fingerprint differs)")
            periodic = _phases_from_dict(d["periodic"])
            dead = float(d.get("dead_time", 0.0))
            pattern = SamplePattern(float(d["rate"]), tuple(Cycle(h, dead) for h in d["cycles"]), int(d["repeat"]),
                                    tuple(p.channel for p in periodic), tuple(int(k) for k in d["ties"]),
                                    tuple(p.rows is not None for p in periodic) if dead else ())
            return cls(system, NoiseModel.from_dict(d["noise"]), pattern, periodic, _phases_from_dict(d["startup"]),
                       int(d["periods"]), float(d["change"]), np.asarray(d["error_transition"], dtype=float),
                       float(d["rho"]), float(d["norm"]), float(d.get("startup_change", 0.0)))
        except (KeyError, TypeError, AttributeError) as err:
            raise KalmanDesignError(f"stored Kalman design is malformed (missing or bad {err})") from None

    def describe(self) -> str:
        """One line: rate, cycles, period, start-up length, convergence, rho and norm."""
        capped = (f" (capped {self.startup_change:.2g} from the periodic solution)"
                  if self.startup_change > 1e-9 else "")
        return (
            f"kalman: {self.rate:g} Hz, {', '.join(c.label() for c in self.cycles)}, period {self.pattern.K} samples, "
            f"start-up {len(self.startup)} samples{capped}, solved in {self.periods} doublings and sweeps, "
            f"period error transition rho = {self.rho:.4g}, ||.|| = {self.norm:.4g}"
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
) -> KalmanDesign:
    """Offline periodic Kalman gains for ``cycles`` (one cycle, or a sequence repeated) at ``rate`` Hz.

    ``design = design_kalman(system, Cycle.from_ts(2.0, 0.6), 50.0, default_noise(system))``

    Steps: 1. sample pattern over one period; 2. detectability of the sampled periodic pair;
    3. periodic Riccati solution by doubling (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`,
    residual ``<= rtol``), and the start-up segment from ``P0`` (``startup_rtol``, at most
    ``max_startup`` samples: default 64 periods, at most what :data:`STARTUP_BUDGET_BYTES` of
    priors hold but at least one period: :func:`~switchobs_core.design.doubling.startup_run`);
    4. the period's error transition.

    Raises
    ------
    KalmanDesignError
        No whole number of samples per period (see :func:`sample_pattern`).
    UndetectableSchedule
        Some unstable mode is never observed by the sampled schedule.
    RiccatiError
        The doubling does not settle, or its solution is not stabilising.
    """
    noise = default_noise(system) if noise is None else noise
    if not isinstance(noise, NoiseModel):
        raise InvalidArgument(f"noise must be a NoiseModel; got {type(noise).__name__}")
    noise.check_system(system)
    # 1. sample pattern (of cycles short enough to be represented, see check_cycle_horizon)
    for c in [cycles] if isinstance(cycles, Cycle) else list(cycles):
        if isinstance(c, Cycle):
            check_cycle_horizon(system.A, c)
    pattern = design_pattern(system, cycles, rate, max_repeat=max_repeat, max_startup=max_startup)
    # 2. detectability
    check_detectable(system, pattern)
    # 3. periodic Riccati solution and start-up
    A = np.asarray(system.A, dtype=float)
    dt = 1.0 / pattern.rate
    Phi, _, Qd = discretize(A, np.asarray(system.B, dtype=float), noise.Q_c, dt)
    K = pattern.K
    rows = [pattern.rows(k, system) for k in range(K)]
    steps = [Step(Phi, Qd, system.C[c - 1] if r is None else system.C[c - 1][list(r)], noise.R(c, r))
             for c, r in zip(pattern.channels, rows)]
    sol = solve_periodic_riccati(steps, rtol=rtol)
    if max_startup is None:
        max_startup = startup_cap(K, A.shape[0])
    # max_startup = 0: no start-up segment (its distance: P0 from the periodic prior of phase 0)
    su_P, su_K, su_change = [], [], rel_change(noise.P0, sol.P_prior[0])
    if max_startup > 0:
        su_P, su_K, su_change = startup_run(steps, sol.P_prior, noise.P0, rtol=startup_rtol, max_samples=max_startup)
    periodic = [KalmanPhase(pattern.channels[k], dt, sol.P_prior[k], sol.K[k], rows[k]) for k in range(K)]
    startup = [KalmanPhase(pattern.channels[k % K], 0.0 if k == 0 else dt, P, Kk, rows[k % K])
               for k, (P, Kk) in enumerate(zip(su_P, su_K))]
    # 4. error transition over one period: e+_{k+1} = (I - K H) Phi e+_k, phases 1..K-1 then 0
    M = sol.transition
    return KalmanDesign(system, noise, pattern, periodic, startup, sol.periods, sol.change, M, sol.rho,
                        float(np.linalg.norm(M, 2)), su_change)


class TableKalman:
    """The table-lookup filter: exact prediction, correction with the stored gain of the phase.

    ``f = TableKalman(design, x0)``; ``x = f.update(t, channel, y, rows=None, u=None)`` with ``t``
    the time since the cycle sequence started. Uses the same step formulas as the online
    filter (:mod:`switchobs_core.design.riccati`); no covariance is propagated (module docstring).
    """

    def __init__(self, design: KalmanDesign, x0: Any = None) -> None:
        self.design = design
        sysm = design.system
        n = sysm.n
        self.x = np.zeros(n) if x0 is None else np.array(x0, dtype=float).reshape(n)
        self.t: float | None = None
        self.phase: Phase | None = None
        self._cache = DiscretizationCache(np.asarray(sysm.A, float), np.asarray(sysm.B, float), np.zeros((n, n)))

    def update(self, t: float, channel: int, y: Any, rows: Sequence[int] | None = None, u: Any = None) -> np.ndarray:
        """Predict to ``t`` (``u`` held since the last sample), correct with ``y`` (rows ``rows``)."""
        if self.t is not None:
            Phi, GB, _ = self._cache.get(t - self.t)
            # x^- = Phi x^+ + Gamma B u
            self.x = Phi @ self.x if u is None else Phi @ self.x + GB @ np.asarray(u, float)
        self.t = float(t)
        self.phase = ph = self.design.phase_at(t)
        K = self.design.gain(ph, channel, rows)
        self.x = correct_state(self.x, K, self.design.H(channel, rows), np.asarray(y, dtype=float))
        return self.x
