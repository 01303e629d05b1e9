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
Departure (any other sample)
    partial rows, a missing sample, a channel other than the phase's, a stamp off the grid or a
    step off the design's ``dt``, a state set from outside: the real covariance (the stored
    posterior of the last locked sample, propagated exactly to this sample) becomes the
    observer's own and the Riccati recursion runs online from it (:mod:`switchobs_core.runtime.families.online`).
Re-lock
    at the first sample of the designed pattern whose online prior ``P^-`` is within
    ``relock_rtol`` of the stored prior ``S`` of its phase, every entry on its own scale
    (``|P^- - S|_ij <= relock_rtol sqrt(S_ii S_jj)``: a test relative to ``max|S|`` alone let the
    small, well-measured entries differ by 2 % after a re-lock in the start-up): from there the
    gains are the table's again. The remaining difference does not vanish at once
    (the closed loop contracts over a period, not at every sample): with the default 1e-3 the
    published covariance stays within the 1 % of test_kalman_table_cache.py (0.11 % at worst in
    six 20 s runs with 5 % partial samples; 1e-2 with a test relative to ``max|S|`` gave 5.8 %).

``dt_tol`` (seconds) is the step error whose effect on the prior stays inside a tenth of that
tolerance: ``||P(dt') - P(dt)|| <= |dt' - dt| (2 ||A|| ||S|| + ||Q_c||)`` to first order, so
``dt_tol = 0.1 relock_rtol max|S_0| / (2 ||A||_2 max|S_0| + ||Q_c||_2)``, at most a quarter of a
sample period (plus the spacing of the stamps' doubles, ``4e-16 |t|``).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ...bounds.kalman_map import KalmanMap
from ...design.kalman import design_kalman
from ...exceptions import InvalidArgument
from ...table.gains import kalman_table
from ...table.kalman import Phase
from .online import OnlineKalmanGains, kalman_correct

__all__ = ["KalmanTableGains", "MAX_JITTER"]

#: Largest stamp offset from the Kalman table's sample grid, in sample periods (as phase_at).
MAX_JITTER = 0.25
#: Entries of the fused step cache (phase, channel, dt) before it is cleared.
_FUSED_MAX = 8192


class KalmanTableGains(OnlineKalmanGains):
    """The ``kalman`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``KalmanTableGains(obs, table, mode, cycles, noise=None, relock_rtol=1e-3)``; ``noise``, if
    given, must be the table's noise model.

    Attributes
    ----------
    departures, relocks : int
        Counts since the last reset.
    fallback : str
        Why the latest departure happened.
    dt_tol : float
        Largest step error (s) served from the table (module docstring).
    """

    name: ClassVar[str] = "kalman"

    def __init__(self, obs: Any, table: Any, mode: str, cycles: Any, *, noise: Any = None,
                 relock_rtol: float = 1e-3, **_: Any) -> None:
        cycles = self._schedule(obs, mode, cycles, None)
        self.kalman = kd = table.kalman_design(cycles, obs.system)
        if noise is not None and noise.fingerprint() != kd.noise.fingerprint():
            raise InvalidArgument("noise differs from the noise model the Kalman table was designed for; "
                                  "design the table again with that noise model")
        self.noise = kd.noise
        self.track_covariance = True
        self.relock_rtol = float(relock_rtol)
        f = kd.pattern.rate
        self._dtn = 1.0 / f             # the design's step (KalmanPhase.dt of every sample k >= 1)
        S0 = kd.periodic[0].P_prior
        s = float(np.abs(S0).max())
        a = 2.0 * obs._nA * s + float(np.linalg.norm(kd.noise.Q_c, 2))
        self.dt_tol = min(0.1 * self.relock_rtol * s / a if a > 0 else math.inf, MAX_JITTER / f)
        self._fused: dict = {}
        self._R: dict = {}

    @classmethod
    def design_table(cls, system: Any, cycles: Any, *, rate: float = 0.0, noise: Any = None, **_: Any) -> Any:
        """Offline periodic Kalman gains for ``cycles`` at ``rate`` Hz
        (:func:`~switchobs_core.design.kalman.design_kalman`)."""
        return kalman_table(system, [design_kalman(system, cycles, rate, noise)])

    # ------------------------------------------------------------------ protocol
    @property
    def source(self) -> str:
        return "online" if self._online else "table"

    def reset(self, obs: Any) -> None:
        self._online = False
        self._origin: float | None = None
        self._last_k = -1           # sample number of the last sample (-1: none; -2: off the grid)
        self._kgain: tuple | None = None
        self.fallback = ""
        self.departures = 0
        self.relocks = 0

    def steps_covariance(self) -> bool:
        return self._online

    def covariance(self, obs: Any) -> np.ndarray:
        """The real covariance after the last sample: the stored posterior of its phase while
        locked (Joseph form from the stored prior), the recursion's own after a departure."""
        if self._online:
            return obs._P.copy()
        g = self._kgain
        if g is None:
            return obs.noise.P0.copy()
        if len(g) == 4:
            g = (Phase(g[0], g[1], g[2], 0.0), g[3], None)
        return self.kalman.posterior(*g)

    def depart(self, obs: Any, why: str) -> None:
        """Leave the cache: the real covariance becomes the observer's own."""
        if not self._online:
            obs._P = self.covariance(obs)
            self._online = True
            self.departures += 1
            self.fallback = why

    # ------------------------------------------------------------------ samples
    def _departure(self, obs: Any, t: float, ph: Phase, ent: Any, channel: int, rows: tuple | None,
                   span: float) -> str:
        """Why a sample is not the one the table expects at ``ph`` ("" if it is)."""
        if ent.channel != channel and not (ent.rows is not None and rows == ent.rows):
            return (f"a sample on channel {channel} at t = {t:.9g} s, where the Kalman table's "
                    f"schedule has channel {ent.channel}")
        if not ent.has_rows(rows):
            want = "all rows" if ent.rows is None else f"rows {list(ent.rows)}"
            got = "all rows" if rows is None else f"rows {list(rows)}"
            return f"a sample with {got} at t = {t:.9g} s, where the Kalman table's phase has {want}"
        if ph.k != self._last_k + 1:
            return (f"sample {ph.k} of the Kalman table's grid at t = {t:.9g} s follows "
                    + ("a sample off the grid" if self._last_k < -1 else
                       f"sample {self._last_k} ({ph.k - self._last_k - 1} missing)"))
        if ph.k > 0 and abs(span - ent.dt) > self.dt_tol + 4e-16 * abs(t):
            return (f"a step of {span:.9g} s at t = {t:.9g} s, {abs(span - ent.dt):.3g} s off the Kalman table's "
                    f"{ent.dt:.9g} s (tolerance {self.dt_tol:.3g} s)")
        return ""

    def sample(self, obs: Any, t: float, dt: float, channel: int, y: np.ndarray, rows: tuple | None) -> None:
        """The table's gain while locked, else the recursion (module docstring).

        ``dt > 0``: the open-loop step over ``dt`` has not been taken yet; the locked path takes
        it with the correction (one fused map per phase and ``dt``).
        """
        if not self._online and rows is None and dt > 0 and self._origin is not None \
                and self._locked(obs, t, dt, channel, y):
            return
        kd = self.kalman
        span = obs._span
        H = obs.rows_of(channel, rows)
        step = None
        if self._online and dt > 0:     # the recursion's prediction (fused with its correction)
            step = self.predict(obs, dt)
            dt = 0.0
        if self._origin is None:
            self._origin = t
        ph, why = None, ""
        try:
            ph = kd.phase_at(t - self._origin, max_jitter=MAX_JITTER)
            ent = kd.entry(ph)
            why = self._departure(obs, t, ph, ent, channel, rows, span)
        except InvalidArgument as err:
            why = str(err)
        self._last_k = -2 if ph is None else ph.k
        if not self._online and why:
            # the real covariance: the last sample's posterior (P0 before the first), propagated
            # exactly to this sample
            first = self._kgain is None
            self.depart(obs, f"{why}; running the Riccati recursion online from here")
            if dt > 0:
                step = self.predict(obs, dt, covariance=not first)
                dt = 0.0
            elif span > 0 and not first:
                obs._propagate_covariance(obs._cache.step(obs._key, span), span)
        elif self._online and not why:
            # every entry within relock_rtol of its own scale: |P - S|_ij <= rtol sqrt(S_ii S_jj)
            S = ent.P_prior
            d = np.sqrt(np.abs(np.diagonal(S)))
            if np.all(np.abs(obs._P - S) <= self.relock_rtol * np.outer(d, d)):
                self._online = False
                self.relocks += 1
        if self._online:
            self.correct_online(obs, channel, rows, H, y, step)
            return
        K = kd.gain(ph, channel, rows)
        self._kgain = (ph, channel, rows)
        if dt > 0:              # x^- = e^{A dt} x^+ (the table's prior is this sample's)
            obs._step(dt, covariance=False)
        kalman_correct(obs, K, H, y, step)

    def _locked(self, obs: Any, t: float, dt: float, channel: int, y: np.ndarray) -> bool:
        """The hot path (locked, all rows, a step to take): the phase found inline and one cached
        :class:`~switchobs_core.bounds.kalman_map.KalmanMap` per (sample, dt). Returns False (nothing done) whenever
        the general path is needed."""
        kd = self.kalman
        tau = t - self._origin
        f = kd.pattern.rate
        k = round(tau * f)
        if k != self._last_k + 1 or abs(tau - k / f) * f > MAX_JITTER \
                or abs(dt - self._dtn) > self.dt_tol + 4e-16 * abs(t):
            return False
        S = len(kd.startup)
        startup = k < S
        idx = k if startup else k % kd.pattern.K
        fk = (startup, idx, channel, round(dt * 1e9))
        hit = self._fused.get(fk)
        if hit is None:
            ent = kd.startup[idx] if startup else kd.periodic[idx]
            if ent.channel != channel or ent.rows is not None:
                return False
            if len(self._fused) >= _FUSED_MAX:
                self._fused.clear()
            hit = self._fused[fk] = KalmanMap(obs._cache.step(obs._key, dt), ent.K, obs.C[channel - 1], obs._I)
        K, H = hit.K, hit.H
        # x^- = e^{A dt} x^+; x^+ = x^- + K (y - H x^-) (innovation first: rounding at the
        # level of the error, not of ||x||); Phi <- (I - K H) e^{A dt} Phi
        b = obs._bound
        x0 = obs._x
        x = hit.predict(x0)
        nu = y - H @ x
        if b is not None:
            x0n = math.sqrt(float(x0 @ x0))
            xmn = math.sqrt(float(x @ x))
        x += K @ nu
        obs._x = x
        obs.apply_map(hit)      # E formed only if Phi or the bound reads it
        if b is not None:
            rc = b.rho_correct(hit.fK, hit.fH, xmn, math.sqrt(float(y @ y)), math.sqrt(float(nu @ nu)),
                               math.sqrt(float(x @ x)))
            b.fused(hit.e, dt, hit, x0n, xmn, rc, K, y.size, channel)
        self._last_k = k
        self._kgain = (startup, idx, k, channel)     # Phase built only if P is asked for
        return True
