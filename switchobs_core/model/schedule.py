"""Switching cycles and schedules (e:switching_instants, e:tau_k, e:s_k).

Channels are visited in the fixed cyclic order 1, 2, ..., N. A cycle k is the interval
from one channel-1 start to the next; channel i is active for h_i seconds in it, so
tau = h_1 + ... + h_N. For two channels the paper writes (tau, s) with h_1 = s tau and
h_2 = (1 - s) tau.

Dead time (beyond the paper). A camera needs time to turn: for the first ``d`` seconds of
every residence (a *blind* interval after each switching instant) only the rows that every
channel shares are measured (the camera's own pose; :func:`common_rows`). ``Cycle(h,
dead_time=d)`` keeps ``h_i`` as channel i's whole residence (switch to switch), so ``tau`` and
``s`` mean what they meant; channel i *sees* its target for ``h_i - d`` seconds (:meth:`Cycle.active`)
and is blind to it for ``tau - h_i + d`` (:meth:`Cycle.inactive`): for the paper's LMI gains the
blind interval is an extra inactive interval of every channel.

Schedules say which channel is active when:

* :class:`PeriodicSchedule` -- one cycle repeated (the paper's periodic case);
* :class:`SequenceSchedule` -- a list of cycles, repeated (the paper's nonperiodic case);
* :class:`RandomSchedule` -- residence times drawn uniformly from [h_min, h_max]
  (assumption A2), seeded: a test bench for robust designs.

Ties. A time at a switching instant belongs to the channel that starts there, and a time within
:data:`TIE` (half a nanosecond) before one counts as at it: stamps are whole nanoseconds, and the
float arithmetic of a time ``t`` (``k / f``, ``t0 + k / f``, ``fmod``) is within ``1e-16 |t|`` of
its nanosecond, so every schedule method here, the simulators, the Kalman design's sample
pattern (:func:`~switchobs_core.design.kalman.sample_pattern`, which asks :meth:`Schedule.channel_at`)
and a stream generated from a schedule assign a sample at a switching instant to one channel, the
new one. (``fmod(4.2, 2.5)`` is ``1.7000000000000002`` while the design's sample at 1.7 s gives
``1.7``: without the rule one of them saw the old channel.)

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import ScheduleError
from ..numerics.scaling import balanced_norm
from ..validation import as_finite

__all__ = [
    "Cycle",
    "Schedule",
    "PeriodicSchedule",
    "SequenceSchedule",
    "RandomSchedule",
    "parse_schedule",
    "CYCLE_RTOL",
    "CYCLE_ATOL",
    "MAX_NORM_TAU",
    "check_cycle_horizon",
    "common_rows",
    "BLIND_TOL",
    "TIE",
]

#: A time within this many seconds before the end of a blind interval counts as seeing (the
#: tie rule of :meth:`Schedule.blind_at`, shared by the simulators, the Kalman sample pattern
#: and the observer: a sample at exactly ``switch + d`` in floating point is not blind).
BLIND_TOL = 1e-9

#: A time this close before a switching instant is at it (module docstring: ties): half a nanosecond.
TIE = 0.5e-9

#: Largest ``min(||A||_2, ||A_b||_2) tau`` of a cycle (``A_b`` the balanced ``A``,
#: :func:`~switchobs_core.numerics.scaling.balanced_norm`): beyond it ``e^{A tau}`` (the open-loop
#: transition over one cycle) leaves double precision (``e^709`` overflows), and designs and
#: certificates computed from it are meaningless (a 1e9 s cycle designed and said "converges" with f = 0).
MAX_NORM_TAU = 600.0


def check_cycle_horizon(A: Any, cycle: Cycle, what: str = "--cycle") -> None:
    """Refuse a cycle too long for the system to be represented in floating point
    (``min(||A||_2, ||A_b||_2) tau > MAX_NORM_TAU``), naming the longest tau that works.

    ``A_b`` is ``A`` in balanced coordinates (:mod:`switchobs_core.numerics.scaling`): its norm
    bounds the growth rate of ``e^{A t}`` in those coordinates, and it does not depend on the units
    of the state (a 10 Hz oscillator in SI units has ``||A||_2 = 3.9e3`` from ``omega^2`` alone,
    and ``||A_b||_2 = 65``); the smaller of the two norms decides."""
    A = np.asarray(A, dtype=float)
    nA = min(float(np.linalg.norm(A, 2)), balanced_norm(A)) if A.size else 0.0
    if nA * cycle.tau > MAX_NORM_TAU:
        raise ScheduleError(f"{what} {cycle.label()}: tau = {cycle.tau:g} s is too long for this system: the "
                            f"transition over one cycle, e^(A tau) with ||A|| = {nA:.3g} (in balanced units), "
                            f"leaves double precision; use tau <= {MAX_NORM_TAU / nA:.4g} s")

#: Default tolerance of :meth:`Cycle.matches` (relative, absolute in seconds).
CYCLE_RTOL = 1e-6
CYCLE_ATOL = 1e-9


def common_rows(C: Sequence[Any]) -> tuple[int, ...]:
    """The rows every channel measures: positions r where row r of every ``C_i`` is the same
    (bit for bit). For the camera model the camera's own position, rows 0 and 1. These rows are
    what a blind interval measures (module docstring); none (``()``) means fully blind."""
    try:
        mats = [np.asarray(Ci, dtype=float) for Ci in C]
    except (TypeError, ValueError):
        raise ScheduleError(f"C must be a sequence of output matrices C_1..C_N; got {C!r}") from None
    if not mats or any(m.ndim != 2 or m.shape[1] != mats[0].shape[1] for m in mats):
        raise ScheduleError("C must hold one or more output matrices (p_i x n), all with the same n columns")
    p = min(m.shape[0] for m in mats)
    return tuple(r for r in range(p) if all(np.array_equal(m[r], mats[0][r]) for m in mats[1:]))


@dataclass(frozen=True)
class Cycle:
    """One switching cycle: channel i active for h[i - 1] seconds, in order 1..N.

    ``Cycle((h_1, ..., h_N))`` or ``Cycle.from_ts(tau, s)`` for two channels; with
    ``dead_time=d`` the first ``d`` seconds of every residence are blind (module docstring).

    Raises
    ------
    ScheduleError
        Fewer than two channels, a non-finite or non-positive active time, a dead time < 0 or
        not shorter than every residence.
    """

    h: tuple[float, ...]
    dead_time: float = 0.0

    def __init__(self, h: Sequence[float], dead_time: float = 0.0) -> None:
        try:
            hs = tuple(as_finite(x, f"h_{i + 1}") for i, x in enumerate(h))
        except Exception as err:
            raise ScheduleError(f"bad cycle {h!r}: {err}") from None
        if len(hs) < 2:
            raise ScheduleError(f"h: a cycle needs active times h_1..h_N for N >= 2 channels; got {len(hs)}")
        for i, x in enumerate(hs):
            if x <= 0:
                raise ScheduleError(f"active time h_{i + 1} must be > 0; got {x}")
        try:
            d = as_finite(dead_time, "dead_time")
        except Exception as err:
            raise ScheduleError(f"bad dead time: {err}") from None
        if d < 0:
            raise ScheduleError(f"dead time must be >= 0 s; got {d:g}")
        if d >= min(hs):
            i = int(np.argmin(hs))
            raise ScheduleError(f"dead time {d:g} s leaves channel {i + 1} nothing to see: its residence h_{i + 1} = "
                                f"{hs[i]:g} s must be longer than the dead time")
        object.__setattr__(self, "h", hs)
        object.__setattr__(self, "dead_time", float(d))

    def with_dead_time(self, dead_time: float) -> Cycle:
        """The same residences with blind intervals of ``dead_time`` seconds after each switch."""
        return Cycle(self.h, dead_time)

    @classmethod
    def from_ts(cls, tau: float, s: float, dead_time: float = 0.0) -> Cycle:
        """Two-channel cycle of length tau > 0 with duty fraction s in (0, 1) (e:s_k)."""
        tau = as_finite(tau, "tau")
        s = as_finite(s, "s")
        if tau <= 0:
            raise ScheduleError(f"cycle length tau must be > 0; got {tau}")
        if not 0 < s < 1:
            raise ScheduleError(f"duty fraction s must lie in (0, 1); got {s}")
        return cls((s * tau, (1 - s) * tau), dead_time)

    @property
    def N(self) -> int:
        """Number of channels."""
        return len(self.h)

    @property
    def tau(self) -> float:
        """Cycle length tau = sum h_i (e:tau_k)."""
        return float(sum(self.h))

    @property
    def s(self) -> float:
        """Duty fraction of channel 1, h_1 / tau (e:s_k)."""
        return self.h[0] / self.tau

    def active(self, channel: int) -> float:
        """h_channel - d: how long channel ``channel`` (1-based) sees its target in this cycle."""
        return self.h[channel - 1] - self.dead_time

    def inactive(self, channel: int) -> float:
        """tau - h_channel + d: how long channel ``channel`` (1-based) is off (or blind) in this cycle."""
        return self.tau - self.h[channel - 1] + self.dead_time

    def matches(self, other: Cycle, *, rtol: float = CYCLE_RTOL, atol: float = CYCLE_ATOL) -> bool:
        """Whether every active time and the dead time agree within ``atol + rtol * tau``."""
        if other.N != self.N:
            return False
        tol = atol + rtol * max(self.tau, other.tau)
        return all(abs(a - b) <= tol for a, b in zip(self.h, other.h)) and \
            abs(self.dead_time - other.dead_time) <= tol

    def label(self) -> str:
        """``(tau, s)`` for two channels, ``h=(h_1, ..., h_N)`` otherwise; ``dead d s`` appended."""
        dead = f", dead {self.dead_time:g} s" if self.dead_time else ""
        if self.N == 2:
            return f"({self.tau:g} s, {self.s:g}{dead})"
        return "h=(" + ", ".join(f"{x:g}" for x in self.h) + dead + ")"

    def to_dict(self) -> dict:
        """JSON-ready form (``dead_time`` only when > 0, so tables without one keep their bytes)."""
        out: dict = {"tau": self.tau, "h": list(self.h)}
        if self.dead_time:
            out["dead_time"] = self.dead_time
        return out


class Schedule:
    """Which channel is active when; cycles start at t0 with channel 1."""

    t0: float = 0.0

    def cycle(self, k: int) -> Cycle:
        """The k-th cycle (k = 0, 1, ...)."""
        raise NotImplementedError

    @property
    def N(self) -> int:
        """Number of channels."""
        return self.cycle(0).N

    def switching_instants(self, t_end: float) -> np.ndarray:
        """All switching instants t_l in [t0, t_end), starting with t0 (e:switching_instants)."""
        t_end = as_finite(t_end, "t_end")
        out, t, k = [], self.t0, 0
        while t < t_end:
            for h in self.cycle(k).h:
                if t >= t_end:
                    break
                out.append(t)
                t += h
            k += 1
        return np.asarray(out)

    def _locate(self, t: float) -> tuple[Cycle | None, int, float]:
        """``(cycle, channel, time since the channel's switching instant)`` at ``t`` (the tie rule of
        the module docstring: the time since may be down to ``-TIE``); before t0 ``(None, 1, 0.0)``.
        The one walk over the cycles that :meth:`channel_at`, :meth:`slot_at` and :meth:`blind_at`
        share. It resumes at the cycle the previous call ended in when that cycle starts at or before
        ``t`` (else at t0): the cycle starts are the same sums, in the same order, as a walk from t0,
        so the answer is the same, and a run that asks at increasing times walks each cycle once."""
        t = as_finite(t, "t") + TIE
        if t < self.t0:
            return None, 1, 0.0
        cur = getattr(self, "_walk", None)
        if cur is not None and cur[0] == self.t0 and cur[1] <= t:
            _, tt, k = cur
        else:
            tt, k = self.t0, 0
        while True:
            c = self.cycle(k)
            if t < tt + c.tau:
                self._walk = (self.t0, tt, k)
                off = t - tt
                acc = 0.0
                for i, h in enumerate(c.h):
                    if off < acc + h or i == c.N - 1:
                        return c, i + 1, off - acc - TIE
                    acc += h
            tt += c.tau
            k += 1

    def slot_at(self, t: float) -> tuple[int, float]:
        """``(channel, time since its switching instant)`` at ``t`` (channel 1 before t0)."""
        _, ch, off = self._locate(t)
        return ch, off

    def blind_at(self, t: float) -> bool:
        """Whether ``t`` lies in the blind interval after a switching instant (module
        docstring): less than ``d - BLIND_TOL`` seconds into its residence (never before t0)."""
        c, _, off = self._locate(t)
        return c is not None and bool(c.dead_time) and off < c.dead_time - BLIND_TOL

    def channel_at(self, t: float) -> int:
        """The active channel rho(t) in 1..N (channel 1 before t0; a tie is the new channel)."""
        return self._locate(t)[1]


class PeriodicSchedule(Schedule):
    """One cycle repeated forever (the paper's periodic case)."""

    def __init__(self, cycle: Cycle, t0: float = 0.0) -> None:
        if not isinstance(cycle, Cycle):
            raise ScheduleError(f"cycle must be a Cycle (e.g. Cycle.from_ts(2.0, 0.6)); got {cycle!r}")
        self._cycle = cycle
        self.t0 = as_finite(t0, "t0")
        self._starts = np.concatenate([[0.0], np.cumsum(cycle.h)])

    def cycle(self, k: int) -> Cycle:
        return self._cycle

    @property
    def cycles(self) -> list[Cycle]:
        """The cycle types of the schedule."""
        return [self._cycle]

    def _offset(self, t: float) -> tuple[int, float]:
        """``(channel index, time since its switching instant)`` at ``t >= t0``, ties as the module
        docstring says."""
        tau = self._cycle.tau
        off = (t - self.t0) % tau + TIE
        if off >= tau:
            off -= tau
        i = min(max(bisect.bisect_right(self._starts, off) - 1, 0), self._cycle.N - 1)
        return i, off - self._starts[i] - TIE

    def channel_at(self, t: float) -> int:
        if not math.isfinite(t):
            raise ScheduleError(f"t must be a finite time; got {t!r}")
        if t + TIE < self.t0:
            return 1
        return self._offset(t)[0] + 1

    def blind_at(self, t: float) -> bool:
        d = self._cycle.dead_time
        if not d or not math.isfinite(t) or t + TIE < self.t0:
            return False
        return self._offset(t)[1] < d - BLIND_TOL


class SequenceSchedule(Schedule):
    """A list of cycles, repeated (the paper's nonperiodic case)."""

    def __init__(self, cycles: Sequence[Cycle], t0: float = 0.0) -> None:
        cycles = list(cycles)
        if not cycles:
            raise ScheduleError("cycles: a sequence schedule needs at least one cycle")
        for k, c in enumerate(cycles):
            if not isinstance(c, Cycle):
                raise ScheduleError(f"cycles[{k}] must be a Cycle; got {c!r}")
        if len({c.N for c in cycles}) != 1:
            raise ScheduleError("cycles: all cycles of a schedule must have the same number of channels")
        self._cycles = cycles
        self.t0 = as_finite(t0, "t0")

    def cycle(self, k: int) -> Cycle:
        return self._cycles[k % len(self._cycles)]

    @property
    def cycles(self) -> list[Cycle]:
        """The cycle list (one period)."""
        return list(self._cycles)


class RandomSchedule(Schedule):
    """Residence times drawn uniformly from [h_min, h_max] (assumption A2), seeded."""

    def __init__(self, N: int, h_min: float, h_max: float, *, seed: int = 0, t0: float = 0.0) -> None:
        h_min, h_max = as_finite(h_min, "h_min"), as_finite(h_max, "h_max")
        if not 0 < h_min <= h_max:
            raise ScheduleError(f"need 0 < h_min <= h_max; got [{h_min}, {h_max}]")
        if not isinstance(N, (int, np.integer)) or N < 2:
            raise ScheduleError(f"N: need an integer N >= 2 channels; got {N!r}")
        self.N_ = int(N)
        self.h_min, self.h_max = h_min, h_max
        self.t0 = as_finite(t0, "t0")
        self._rng = np.random.default_rng(seed)
        self._drawn: list[Cycle] = []

    def cycle(self, k: int) -> Cycle:
        while len(self._drawn) <= k:
            self._drawn.append(Cycle(self._rng.uniform(self.h_min, self.h_max, self.N_)))
        return self._drawn[k]


def parse_schedule(text: str, *, N: int = 2, dead_time: float = 0.0) -> Schedule:
    """Parse ``periodic:TAU,S``, ``periodic-h:H1,...,HN``, ``sequence:T,S;T,S;...`` or
    ``random:HMIN,HMAX[,SEED]``; ``dead_time`` (s) is given to every cycle (module docstring).
    """
    sch = _parse_schedule(text, N=N)
    if dead_time:
        if isinstance(sch, PeriodicSchedule):
            return PeriodicSchedule(sch.cycle(0).with_dead_time(dead_time))
        if isinstance(sch, SequenceSchedule):
            return SequenceSchedule([c.with_dead_time(dead_time) for c in sch.cycles])
        raise ScheduleError("a dead time needs a periodic or sequence schedule (random residences are not "
                            "supported with a dead time)")
    return sch


def _parse_schedule(text: str, *, N: int = 2) -> Schedule:
    kind, _, rest = text.partition(":")
    try:
        if kind == "periodic":
            tau, s = (float(x) for x in rest.split(","))
            return PeriodicSchedule(Cycle.from_ts(tau, s))
        if kind == "periodic-h":
            return PeriodicSchedule(Cycle([float(x) for x in rest.split(",")]))
        if kind == "sequence":
            cycles = []
            for part in rest.replace(" ", ";").split(";"):
                if part:
                    tau, s = (float(x) for x in part.split(","))
                    cycles.append(Cycle.from_ts(tau, s))
            return SequenceSchedule(cycles)
        if kind == "random":
            vals = rest.split(",")
            seed = int(vals[2]) if len(vals) > 2 else 0
            return RandomSchedule(N, float(vals[0]), float(vals[1]), seed=seed)
    except ValueError as err:
        if isinstance(err, ScheduleError):
            raise
        raise ScheduleError(f"cannot parse schedule '{text}': {err}") from None
    except TypeError as err:
        raise ScheduleError(f"schedule must be a string like periodic:2,0.6; got {text!r} ({err})") from None
    raise ScheduleError(
        f"unknown schedule '{text}'; use periodic:TAU,S, periodic-h:H1,..,HN, "
        "sequence:T,S;T,S;... or random:HMIN,HMAX[,SEED]"
    )
