"""The Kalman table family: offline periodic Kalman gains as an exact cache of the recursion.

The Riccati recursion depends only on the sample pattern, ``Q_c``, ``R`` and ``P0``, not on the
data (:mod:`switchobs_core.design.kalman`), so for the designed pattern the stored gains *are* the online filter's.
The table is used only while that holds: while the observer's real covariance is the stored one.

Locked (the cache is valid)
    a sample at the phase ``k`` the table expects next (``k = k_prev + 1``: no sample missing),
    on the phase's channel with the phase's rows, ``dt`` within :attr:`KalmanTableGains.dt_tol`
    of the design's ``1 / f``: the stored gain, one fused map ``E = (I - K H) e^{A dt}`` per
    (phase, dt), O(n^2) per sample. The real covariance is the stored posterior of the phase
    (published on demand, :meth:`KalmanTableGains.covariance`).
Missing samples (:attr:`KalmanTableGains.missing` ``"table"``, the default)
    a sample ``k > k_prev + 1`` on the grid, otherwise locked (its phase's channel and rows, a
    step of ``k - k_prev`` design steps within ``dt_tol``): the table stays on its grid and the real
    covariance is the stored one plus ``U U'``, a deviation of low rank carried with the filter's
    own gain for the real prior (:mod:`~switchobs_core.runtime.families.gaps`): the optimal
    estimate and its covariance at ``O(n^2 r)`` a sample, until the deviation retires at the
    re-lock test's tolerance. The counts: :attr:`KalmanTableGains.gaps`,
    :attr:`KalmanTableGains.gaps_retired`. With ``missing="online"`` a missing sample is a departure.
Departure (any other sample)
    partial rows, a missing sample (``missing="online"``, or a deviation past
    :data:`~switchobs_core.runtime.families.gaps.GAP_MAX`), a channel other than the phase's, a
    stamp off the grid or a step off the design's ``dt``, a state set from outside: the real covariance (the stored
    posterior of the last locked sample, propagated exactly to this sample) becomes the
    family's own and the Riccati recursion runs online from it (:mod:`switchobs_core.runtime.families.online`).
Re-lock
    at the first sample of the designed pattern whose online prior ``P^-`` is within
    ``relock_rtol`` of the stored prior ``S`` of its phase, every entry on its own scale
    (``|P^- - S|_ij <= relock_rtol sqrt(S_ii S_jj)``: a test relative to ``max|S|`` alone let the
    small, well-measured entries differ by 2 % after a re-lock in the start-up): from there the
    gains are the table's again. The remaining difference does not vanish at once
    (the closed loop contracts over a period, not at every sample): with the default 1e-3 the
    published covariance stays within the 1 % of test_kalman_table_cache.py (0.11 % at worst in
    six 20 s runs with 5 % partial samples; 1e-2 with a test relative to ``max|S|`` gave 5.8 %).

Alignment to the schedule
    the grid starts at the first sample, as phase 0 of the table (its first channel, at the start
    of that channel's residence). A node that starts while the sensors are mid-cycle takes its
    first sample elsewhere in the cycle: it departs there, and at the first switch it sees (two
    consecutive samples, one step apart, on different channels) the grid is moved by a whole
    number of samples so that this sample is the table's first sample of that channel's residence
    in the periodic pattern (when the pattern starts that channel's residence once per period);
    the recursion then re-locks as after any departure, once its prior has converged to the stored
    one.
First sample after t0
    the stored start-up begins with ``P0`` at the first sample; a first sample later than the
    observer's ``t0`` (by more than ``dt_tol``) has the prior ``P0`` propagated exactly over the
    gap instead, so it leaves the cache at once with that prior and re-locks like any departure
    (the table's grid starts at that sample).

Phases in nanoseconds. The grid position of a sample is counted in whole nanoseconds from the
first sample (``round(1e9 t)``), so the float arithmetic of a stamp never moves a sample to
another phase; the channel of a sample at a switching instant follows the schedule's tie rule,
which the design's sample pattern used too (:mod:`switchobs_core.model.schedule`).

``dt_tol`` (seconds) is the step error whose effect on the prior stays inside a tenth of that
tolerance, in the balanced coordinates of ``A`` (:mod:`switchobs_core.numerics.scaling`: ``A_b =
D^-1 A D``, ``S_b = D^-1 S D^-1``, ``Q_b`` likewise): ``||P(dt') - P(dt)|| <= |dt' - dt| (2 ||A_b||
||S_b|| + ||Q_b||)`` to first order, so ``dt_tol = 0.1 relock_rtol max|S_b| / (2 ||A_b||_2 max|S_b| +
||Q_b||_2)`` with ``S`` the stored prior of phase 0, at most a quarter of a sample period (plus the
spacing of the stamps' doubles, ``4e-16 |t|``). The units of the state do not change it (with
``||A||_2`` in the user's units a 10 Hz oscillator in SI units, ``||A||_2 = 3.9e3``, got 13 ns).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ...bounds.kalman_map import KalmanMap
from ...exceptions import GainTableError, InvalidArgument
from ...numerics.kalman_step import symmetrize
from ...numerics.scaling import balance, balanced_norm
from ...table.gains import kalman_table
from ...table.kalman import Phase
from ..error_maps import FusedMap, ZohMap, zoh_step
from .base import OPEN_LOOP, Correction, FamilyContext, Sample
from .gaps import GapDeviation
from .online import OnlineKalmanGains, kalman_correct

__all__ = ["KalmanTableGains", "MAX_JITTER", "MISSING"]

#: What a missing sample on the grid does (module docstring, missing samples).
MISSING = ("table", "online")

#: Largest stamp offset from the Kalman table's sample grid, in sample periods (as phase_at).
MAX_JITTER = 0.25
#: Entries of the fused step cache (phase, channel, dt) before it is cleared.
_FUSED_MAX = 8192
_EPS = float(np.finfo(float).eps)


def scaled_cov(S: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``D^-1 S D^-1`` (a covariance in balanced units)."""
    return S / np.outer(d, d)


class KalmanTableGains(OnlineKalmanGains):
    """The ``kalman`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``KalmanTableGains(ctx, table, mode, cycles, noise=None, relock_rtol=1e-3, missing="table")``;
    ``noise``, if given, must be the table's noise model; ``missing`` (also set later, an
    attribute): what a missing sample does (module docstring). Its position in the table (the grid's origin, the
    last sample's phase) and, after a departure, the covariance are its own.

    Attributes
    ----------
    departures, relocks, gaps, gaps_retired : int
        Counts since the last reset (module docstring).
    fallback : str
        Why the latest departure happened.
    dt_tol : float
        Largest step error (s) served from the table (module docstring).
    """

    name: ClassVar[str] = "kalman"

    def __init__(self, ctx: FamilyContext, table: Any, mode: str, cycles: Any, *, noise: Any = None,
                 relock_rtol: float = 1e-3, missing: str = "table", **_: Any) -> None:
        self._ctx = ctx
        cycles = self._schedule(mode, cycles, None)
        self.kalman = kd = table.kalman_design(cycles, ctx.system)
        if noise is not None and noise.fingerprint() != kd.noise.fingerprint():
            raise InvalidArgument("noise differs from the noise model the Kalman table was designed for; "
                                  "design the table again with that noise model")
        self.relock_rtol = float(relock_rtol)
        f = kd.pattern.rate
        self._dtn = 1.0 / f             # the design's step (KalmanPhase.dt of every sample k >= 1)
        self._ns_per_sample = 1e9 / f
        d = balance(ctx.A)
        S0 = scaled_cov(kd.periodic[0].P_prior, d)
        sb = float(np.abs(S0).max())
        a = 2.0 * balanced_norm(ctx.A) * sb + float(np.linalg.norm(scaled_cov(kd.noise.Q_c, d), 2))
        self.dt_tol = min(0.1 * self.relock_rtol * sb / a if a > 0 else math.inf, MAX_JITTER / f)
        self._fused: dict = {}
        self._keep_noise(kd.noise)
        self.missing = missing
        self._gap = GapDeviation(kd, lambda: ctx.zoh(OPEN_LOOP, self._dtn), self.relock_rtol)

    @property
    def missing(self) -> str:
        """What a missing sample on the grid does: ``"table"`` (the table's grid kept, the
        covariance's deviation from the stored one in low rank and the filter's gain for it,
        :mod:`~switchobs_core.runtime.families.gaps`) or ``"online"`` (a departure: the Riccati
        recursion until it re-locks)."""
        return self._missing

    @missing.setter
    def missing(self, how: str) -> None:
        if how not in MISSING:
            raise InvalidArgument(f"missing must be one of {', '.join(MISSING)}; got {how!r}")
        self._missing = how

    gaps = property(lambda self: self._gap.gaps,
                    doc="Samples served from the table after missing ones (since the last reset).")
    gaps_retired = property(lambda self: self._gap.retired,
                            doc="Deviations of missing samples retired (module gaps), since the last reset.")

    @classmethod
    def design_table(cls, system: Any, cycles: Any, *, rate: float = 0.0, noise: Any = None, **_: Any) -> Any:
        """Offline periodic Kalman gains for ``cycles`` at ``rate`` Hz
        (:func:`~switchobs_core.design.kalman.design_kalman`, imported here: by the start that designs, not
        by one that loads a table)."""
        from ...design.kalman import design_kalman
        return kalman_table(system, [design_kalman(system, cycles, rate, noise)])

    # ------------------------------------------------------------------ protocol
    @property
    def source(self) -> str:
        return "online" if self._online else "table"

    def reset(self) -> None:
        super().reset()
        self._online = False
        self._origin: float | None = None
        self._origin_ns = 0
        self._last_k = -1           # sample number of the last sample (-1: none; -2: off the grid)
        self._last_channel = 0      # the last sample's channel (0: none)
        self.alignments = 0         # grid moves to the schedule (module docstring)
        self._kgain: tuple | None = None
        self.fallback = ""
        self.departures = 0
        self.relocks = 0
        self._gap.reset()

    def _since(self, t: float) -> float:
        """Seconds from the first sample to ``t``, counted in whole nanoseconds (module docstring)."""
        return (round(t * 1e9) - self._origin_ns) * 1e-9

    def stepped(self, e: Any, dt: float) -> None:
        """The recursion's prediction after a departure (locked, the table's prior is the real one)."""
        if self._online:
            super().stepped(e, dt)

    def covariance(self) -> np.ndarray:
        """The real covariance after the last sample: the stored posterior of its phase while
        locked (Joseph form from the stored prior) plus ``U U'`` after missing samples
        (:mod:`~switchobs_core.runtime.families.gaps`), the recursion's own after a departure."""
        if self._online:
            return self._P.copy()
        g = self._kgain
        if g is None:
            return self.noise.P0.copy()
        if len(g) == 4:
            g = (Phase(g[0], g[1], g[2], 0.0), g[3], None)
        P = self.kalman.posterior(*g)
        U = self._gap.U
        return P if U is None else symmetrize(P + U @ U.T)

    def stored_prior(self, t: float, dt: float, cols: np.ndarray | None = None) -> np.ndarray | None:
        """While locked, a time ``t`` that is the next sample's on the grid (as :meth:`_locked` tests
        it): the stored prior of that phase, the real prior there whatever the sample's channel
        (no O(n^3) posterior and propagation; a read-only view of the table's matrix, not a copy;
        with ``cols``, its block on those rows and columns, read from the packed row); after a
        departure the recursion's block (:meth:`OnlineKalmanGains.stored_prior`); else None. After
        missing samples on the grid, the stored prior plus ``V V'`` of the deviation
        (:mod:`~switchobs_core.runtime.families.gaps`; a new array)."""
        if self._online:
            return super().stored_prior(t, dt, cols)
        if self._origin is None or self._last_k < 0:
            return None
        k = self._next_k(t, dt)
        if k is None:
            return None
        gap = self._gap
        ent = gap.entry(k)
        try:        # none held and none missing (the grid's next sample): no deviation, as prior() finds
            V = None if gap.U is None and k == self._last_k + 1 else gap.prior(self._last_k, k)
        except GainTableError:      # a missing phase's row is unreadable: the sample will depart
            return None
        if V is not None:
            if cols is not None:
                Vc = V[cols]
                return symmetrize(ent.P_block(cols) + Vc @ Vc.T)
            return symmetrize(ent.P_prior + V @ V.T)
        if cols is not None:
            return ent.P_block(cols)
        P = ent.P_prior.view()
        P.flags.writeable = False
        return P

    def _next_k(self, t: float, dt: float) -> int | None:
        """The grid's sample number of ``t`` when it is the next sample after the last one (or,
        with :attr:`missing` ``"table"``, a later one: the samples between missing), within the
        jitter and step tolerances of the locked path (module docstring); else None."""
        tau_ns = round(t * 1e9) - self._origin_ns
        k = round(tau_ns / self._ns_per_sample)
        g = k - self._last_k
        if g < 1 or g > 1 and not self._gap_allowed() or abs(tau_ns - k * self._ns_per_sample) > \
                MAX_JITTER * self._ns_per_sample or abs(dt - g * self._dtn) > self.dt_tol + 4e-16 * abs(t):
            return None
        return k

    def _gap_allowed(self) -> bool:
        """Whether samples missing since the last one keep the table (:attr:`missing`, locked on the grid)."""
        return self._missing == "table" and self._last_k >= 0 and not self._online

    def depart(self, why: str) -> None:
        """Leave the cache: the real covariance becomes the family's own."""
        if not self._online:
            self._P = self.covariance()
            self._gap.clear()
            self._online = True
            self.departures += 1
            self.fallback = why

    # ------------------------------------------------------------------ samples
    def _departure(self, t: float, ph: Phase, ent: Any, channel: int, rows: tuple | None, span: float) -> str:
        """Why a sample is not the one the table expects at ``ph`` ("" if it is)."""
        if ent.channel != channel and not (ent.rows is not None and rows == ent.rows):
            return (f"a sample on channel {channel} at t = {t:.9g} s, where the Kalman table's "
                    f"schedule has channel {ent.channel}")
        if not ent.has_rows(rows):
            want = "all rows" if ent.rows is None else f"rows {list(ent.rows)}"
            got = "all rows" if rows is None else f"rows {list(rows)}"
            return f"a sample with {got} at t = {t:.9g} s, where the Kalman table's phase has {want}"
        g = ph.k - self._last_k
        if g > 1 and self._gap_allowed():     # samples missing: the table goes on (module gaps)
            if abs(span - g * ent.dt) > self.dt_tol + 4e-16 * abs(t):
                return (f"a step of {span:.9g} s at t = {t:.9g} s over {g - 1} missing samples, "
                        f"{abs(span - g * ent.dt):.3g} s off {g} of the Kalman table's {ent.dt:.9g} s "
                        f"(tolerance {self.dt_tol:.3g} s)")
            try:
                far = self._gap.too_far(self._last_k, ph.k, ent.P_diagonal())
            except GainTableError as err:       # this phase's own row is unreadable
                return f"{g - 1} missing samples before t = {t:.9g} s, and the Kalman table's row: {err}"
            return f"{g - 1} missing samples before t = {t:.9g} s leave {far}" if far else ""
        if g != 1:
            return (f"sample {ph.k} of the Kalman table's grid at t = {t:.9g} s follows "
                    + ("a sample off the grid" if self._last_k < -1 else
                       f"sample {self._last_k} ({ph.k - self._last_k - 1} missing)"))
        if ph.k > 0 and abs(span - ent.dt) > self.dt_tol + 4e-16 * abs(t):
            return (f"a step of {span:.9g} s at t = {t:.9g} s, {abs(span - ent.dt):.3g} s off the Kalman table's "
                    f"{ent.dt:.9g} s (tolerance {self.dt_tol:.3g} s)")
        return ""

    def sample(self, s: Sample) -> Correction:
        """The table's gain while locked, else the recursion (module docstring).

        ``s.dt > 0``: the open-loop step over ``dt`` has not been taken yet; the locked path takes
        it with the correction (one fused map per phase and ``dt``).
        """
        if not self._online and s.rows is None and s.dt > 0 and self._origin is not None:
            c = self._locked(s)
            if c is not None:
                return c
        kd, ctx = self.kalman, self._ctx
        t, dt, span, channel, y, rows = s.t, s.dt, s.span, s.channel, s.y, s.rows
        H = ctx.rows_of(channel, rows)
        x, prediction = s.x, None
        if self._online and dt > 0:     # the recursion's prediction (fused with its correction)
            x, prediction = self.predict(x, dt)
            dt = 0.0
        first, last_k, held = self._origin is None, self._last_k, not self._online
        if first:
            self._origin = t
            self._origin_ns = round(t * 1e9)
        ph, why = None, ""
        try:
            ph = kd.phase_at(self._since(t), max_jitter=MAX_JITTER)
            ent = kd.entry(ph)
            why = self._departure(t, ph, ent, channel, rows, span)
        except InvalidArgument as err:
            why = str(err)
        if first and not why and span > self.dt_tol and not self._online:
            why = (f"the first sample comes {span:.9g} s after t0, where the Kalman table's start-up has the "
                   f"prior P0; its prior is P0 propagated over that time")
        self._last_k = -2 if ph is None else ph.k
        if not self._online and why:
            # the real covariance: the last sample's posterior (P0 at t0 before the first),
            # propagated exactly to this sample
            self.depart(f"{why}; running the Riccati recursion online from here")
            held = False        # not locked from the last sample on: a re-lock below starts afresh
            if dt > 0:
                x, prediction = self.predict(x, dt)
                dt = 0.0
            elif span > 0:
                self._P = self._cov.step(self._P, ctx.zoh(OPEN_LOOP, span), span)
        if self._online and rows is None and self._align(t, channel, span):
            ph = kd.phase_at(self._since(t), max_jitter=MAX_JITTER)
            ent = kd.entry(ph)
            why = self._departure(t, ph, ent, channel, rows, span)
            self._last_k = ph.k
        self._last_channel = channel
        if self._online and not why and not relock_excluded(self._diagonal(), ent.P_diagonal(), self.relock_rtol):
            # every entry within relock_rtol of its own scale: |P - S|_ij <= rtol sqrt(S_ii S_jj)
            S = ent.P_prior
            d = np.sqrt(np.abs(np.diagonal(S)))
            if np.all(np.abs(self._P - S) <= self.relock_rtol * np.outer(d, d)):
                self._online = False
                self.relocks += 1
        if self._online:
            return self.correct_online(channel, rows, H, y, x, prediction)
        K = kd.gain(ph, channel, rows)
        self._kgain = (ph, channel, rows)
        if held and (self._gap.U is not None or ph.k > last_k + 1):     # locked from the last sample on
            K = self._gap.correct(last_k, ph.k, K, H, channel, rows, ent.P_diagonal)
        maps: tuple = ()
        if dt > 0:              # x^- = e^{A dt} x^+ (the table's prior is this sample's; no input was held)
            e = ctx.zoh(OPEN_LOOP, dt)
            xm = zoh_step(e, x, None, None)
            maps = (ZohMap(e, dt, x, xm, None, None),)
            x = xm
        xp, m = kalman_correct(x, K, H, y, self._I, prediction)
        return Correction(xp, maps + (m,))

    def _diagonal(self) -> tuple[np.ndarray, np.ndarray]:
        """The diagonal of the recursion's covariance ``P = L L'`` without forming ``P``: ``(q, err)``
        with ``|P_ii - q_i| <= err_i`` (:func:`relock_excluded`). ``P`` kept as given: its own diagonal,
        ``err = 0``; else ``q_i = sum_k L_ik^2``, and ``P_ii`` (the product's entry; ``(P + P') / 2``
        leaves the diagonal as it is) and ``q_i`` are two sums of the same ``m`` nonnegative terms,
        each within ``gamma_m`` of the exact sum: ``err = 2 gamma_m q / (1 - gamma_m)``, taken twice
        over (rounding of the bound itself)."""
        Pc = self._Pc
        if Pc is not None:
            q = np.diagonal(Pc)
            return q, np.zeros_like(q)
        L = self._L
        q = np.einsum("ij,ij->i", L, L)
        m = L.shape[1] + 2
        return q, q * (4.0 * m * _EPS / (1.0 - m * _EPS))

    def _align(self, t: float, channel: int, span: float) -> bool:
        """At a switch seen one step after the last sample (module docstring, alignment): move the
        grid so that ``t`` is the periodic pattern's first sample of ``channel``. False (nothing
        moved) when no switch is seen here or the pattern does not start that residence once."""
        kd = self.kalman
        if not self._last_channel or self._last_channel == channel or abs(span - self._dtn) > self.dt_tol:
            return False
        per = kd.periodic
        K = len(per)
        starts = [j for j in range(K) if per[j].channel == channel and per[j - 1].channel != channel]
        if len(starts) != 1:
            return False
        S = len(kd.startup)
        k_now = round((round(t * 1e9) - self._origin_ns) / self._ns_per_sample)
        if k_now >= 0 and k_now % K == starts[0]:
            return False              # the grid has it there already (start-up sample k is the pattern's k % K)
        k = starts[0] + K * max(0, -(-(S - starts[0]) // K))     # the first k >= S with k % K on it
        self._origin_ns = round(t * 1e9 - k * self._ns_per_sample)
        self._last_k = k - 1
        self.alignments += 1
        return True

    def _locked(self, s: Sample) -> Correction | None:
        """The hot path (locked, all rows, a step to take): the phase found inline and one cached
        :class:`~switchobs_core.bounds.kalman_map.KalmanMap` per (sample, dt). Returns None (nothing
        done) whenever the general path is needed."""
        kd = self.kalman
        t, dt, channel = s.t, s.dt, s.channel
        k = self._next_k(t, dt)
        if k is None:
            return None
        S = len(kd.startup)
        startup = k < S
        idx = k if startup else k % kd.pattern.K
        fk = (startup, idx, channel, round(dt * 1e9))
        hit = self._fused.get(fk)
        if hit is None:
            ent = kd.startup[idx] if startup else kd.periodic[idx]
            if ent.channel != channel or ent.rows is not None:
                return None
            if len(self._fused) >= _FUSED_MAX:
                self._fused.clear()
            hit = self._fused[fk] = KalmanMap(self._ctx.zoh(OPEN_LOOP, dt), ent.K, self._ctx.C[channel - 1],
                                              self._I)
        K, H = hit.K, hit.H
        gap = self._gap
        if gap.U is not None or k > self._last_k + 1:
            try:
                if k > self._last_k + 1 and gap.too_far(self._last_k, k, gap.entry(k).P_diagonal()):
                    return None         # the general path departs (module gaps)
                K = gap.correct(self._last_k, k, K, H, channel, None, gap.entry(k).P_diagonal)
            except GainTableError:      # this phase's row is unreadable: the general path departs
                return None
            if K is not hit.K:      # the filter's gain of the prior S + V V' (module gaps)
                hit = KalmanMap(hit.e, K, H, self._I)
        # x^- = e^{A dt} x^+; x^+ = x^- + K (y - H x^-) (innovation first: rounding at the
        # level of the error, not of ||x||); the map (I - K H) e^{A dt} for Phi and the bound
        x0 = s.x
        x, nu, xp = hit.correct(x0, s.y)
        self._last_k, self._last_channel = k, channel
        self._kgain = (startup, idx, k, channel)     # Phase built only if P is asked for
        return Correction(xp, (FusedMap(hit, dt, x0, x, xp, s.y, nu, -1 if startup else idx),))

    def periodic_maps(self) -> list[KalmanMap]:
        """The fused maps of the periodic phases at the design's step (the objects the locked path
        uses for a sample on the grid). Raises InvalidArgument when a phase holds partial rows."""
        kd, out = self.kalman, []
        for idx, ent in enumerate(kd.periodic):
            if ent.rows is not None:
                raise InvalidArgument(f"the Kalman table's periodic phase {idx} holds partial rows")
            fk = (False, idx, ent.channel, round(self._dtn * 1e9))
            hit = self._fused.get(fk)
            if hit is None:
                hit = self._fused[fk] = KalmanMap(self._ctx.zoh(OPEN_LOOP, self._dtn), ent.K,
                                                  self._ctx.C[ent.channel - 1], self._I)
            out.append(hit)
        return out


def relock_excluded(diag: tuple[np.ndarray, np.ndarray], S_diag: np.ndarray, rtol: float) -> bool:
    """Whether the re-lock test (module docstring: ``|P - S|_ij <= rtol sqrt(S_ii S_jj)`` for
    every entry) certainly fails on the diagonal, from ``diag = (q, err)`` with ``|P_ii - q_i| <=
    err_i`` and the diagonal ``S_diag`` of the stored prior: True only where some ``i`` has
    ``|q_i - S_ii| - err_i`` above ``rtol |S_ii|`` with room for the test's own roundings (``d_i =
    sqrt|S_ii|`` squared, the products and the difference: a relative ``16 eps``). So a True
    never changes the test's outcome; it spares forming ``P`` (an n x n product) and unpacking
    ``S`` at every sample of the recursion, where the test fails for a whole cycle after a
    departure. A NaN gives False (the full test decides)."""
    q, err = diag
    with np.errstate(all="ignore"):
        gap = np.abs(q - S_diag) * (1.0 - 4.0 * _EPS) - err
        return bool(np.any(gap > rtol * np.abs(S_diag) * (1.0 + 16.0 * _EPS)))
