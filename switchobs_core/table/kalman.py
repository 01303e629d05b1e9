"""Stored periodic Kalman gains: the sample pattern, the stored samples and their lookup (the
``kalman`` gain family's data; beyond the paper).

A :class:`KalmanDesign` holds what :func:`~switchobs_core.design.kalman.design_kalman` computed for
one (super-)cycle at a nominal sample rate f: the :class:`SamplePattern` of one period (the channel
of every sample ``t_k = k / f`` from the start of the cycle sequence, the tie phases, the blind
samples of a dead time), the start-up samples (the recursion from ``P0`` until it meets the periodic
solution) and the periodic ones, each a :class:`KalmanPhase` with its prior ``P^-`` and gain ``K``.
A gain table (:mod:`switchobs_core.table.gains`) stores it with :meth:`KalmanDesign.to_dict` and
rebuilds it with :meth:`KalmanDesign.from_dict`. Its ``noise`` is the model the gains were designed
for, ``Q_c`` the continuous-time spectral density (for a system with a declared disturbance and no
process noise of its own, ``B_w diag(max^2) B_w'``: :mod:`switchobs_core.design.kalman`).

Dead time. The samples in the first ``d`` seconds of every residence are *blind*: they measure
only the rows every channel shares (:func:`~switchobs_core.model.schedule.common_rows`: the
camera's own pose), and their stored step uses ``H = C_rho[common rows]`` (``KalmanPhase.rows``).
``pattern.blind[k]`` says which.

Lookup. :meth:`KalmanDesign.phase_at` maps the time since the sequence start to the nearest
sample (stamp jitter), start-up first, then periodic. A sample with only some rows (a dropped
target pose) gets ``K_r = P^- H_r' (H_r P^- H_r' + R_r)^{-1}`` from the stored prior of its phase
(:func:`~switchobs_core.numerics.kalman_step.gain`), and a sample whose channel differs from its
phase's (a tie: a sample within 1 ns of a switching instant, which floating point gives either
channel from one period to the next) gets its gain the same way. The lookup does not track the
covariance; the run-time family (:mod:`switchobs_core.runtime.families.kalman`) decides when the
stored gains are the filter's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument, KalmanDesignError
from ..model.noise import NoiseModel
from ..model.schedule import Cycle, common_rows
from ..numerics.kalman_step import gain, joseph
from .container import packed_size, unpack_symmetric
from .rows import LazyRow

__all__ = ["SamplePattern", "KalmanPhase", "Phase", "KalmanDesign", "packed_block_index"]


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


#: Index arrays of :func:`packed_block_index`, by ``(n, cols)`` (a few per channel; cleared when full).
_BLOCK_INDEX: dict[tuple, np.ndarray] = {}
_BLOCK_INDEX_MAX = 256


def packed_position(i, j, n: int):
    """Where entry ``(i, j)``, ``i <= j`` (ints or integer arrays), of an n x n symmetric matrix sits
    in its packed upper triangle (row-major): ``i n - i (i - 1) / 2 + (j - i)``."""
    return i * n - i * (i - 1) // 2 + (j - i)


def packed_block_index(n: int, cols: np.ndarray) -> np.ndarray:
    """The positions of ``P[np.ix_(cols, cols)]`` in the packed upper triangle of an n x n symmetric
    ``P`` (row-major): entry ``(i, j)`` of the block at ``min * n - min (min - 1) / 2 + (max - min)``.
    Kept per ``(n, cols)`` (read-only): every phase of a table reads the same few blocks."""
    key = (n, cols.dtype, cols.tobytes())        # the dtype itself: equal (and hashed alike) as its .str
    idx = _BLOCK_INDEX.get(key)
    if idx is None:
        i, j = np.minimum.outer(cols, cols), np.maximum.outer(cols, cols)
        idx = packed_position(i, j, n)
        idx.flags.writeable = False
        if len(_BLOCK_INDEX) >= _BLOCK_INDEX_MAX:
            _BLOCK_INDEX.clear()
        _BLOCK_INDEX[key] = idx
    return idx


@dataclass(frozen=True, eq=False)
class KalmanPhase:
    """One stored sample: ``channel`` (1-based), ``dt`` since the previous sample, prior ``P^-``, gain
    ``K``, and the ``rows`` of ``C_channel`` it measures (None: all; the common rows when blind).

    The prior is given (``P_stored``) as the (n, n) matrix, as its packed upper triangle (what a binary
    table file holds, :mod:`switchobs_core.table.container`), or as a row of a version-4 file not read yet
    (:class:`~switchobs_core.table.rows.LazyRow`); :attr:`P_prior` is the matrix, read, verified and unpacked on
    first use (the same doubles), so loading a large table neither reads nor unpacks every phase."""

    channel: int
    dt: float
    P_stored: np.ndarray | LazyRow
    K: np.ndarray
    rows: tuple[int, ...] | None = None

    @property
    def P_prior(self) -> np.ndarray:
        """The prior covariance ``P^-`` of this sample (n x n); raises
        :class:`~switchobs_core.exceptions.GainTableError` when its stored row fails its checksum."""
        P = self._read()
        if P.ndim == 1:
            P = unpack_symmetric(P, self.K.shape[0])
            object.__setattr__(self, "P_stored", P)
        return P

    def P_block(self, cols: np.ndarray) -> np.ndarray:
        """``P_prior[np.ix_(cols, cols)]`` (the same doubles), from the packed row when the matrix
        has not been unpacked (a phase whose covariance is not published: no n x n matrix made)."""
        P = self._read()
        if P.ndim == 2:
            return P[cols[:, None], cols]       # np.ix_'s block, without its checks
        return P[packed_block_index(self.K.shape[0], cols)]

    def P_diagonal(self) -> np.ndarray:
        """``np.diagonal(P_prior)`` (the same doubles, a new array), from the packed row when the
        matrix has not been unpacked."""
        P = self._read()
        if P.ndim == 2:
            return np.diagonal(P).copy()
        n = self.K.shape[0]
        i = np.arange(n)
        return P[packed_position(i, i, n)]

    def _read(self) -> np.ndarray:
        """The stored prior as it is kept: a row not read yet is read and verified now
        (:class:`~switchobs_core.table.rows.LazyRow`) and kept packed (half the matrix's memory)."""
        P = self.P_stored
        if isinstance(P, LazyRow):
            P = P.load()
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
            if isinstance(P, LazyRow):          # read and verified on first use
                n = P.n
            else:
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
