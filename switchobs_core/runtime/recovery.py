"""Recovery of the guarantee: re-certification, the bias test and a body the gate starves.

One object per observer, called around each sample by whoever runs the consistency tests (the
estimator's screening, :mod:`switchobs_core.sim.faults`):

``before(t, channel, rows, y)``
    the CUSUM of :mod:`switchobs_core.runtime.bias` on the sample's normalised innovations against
    the prior; returns the alarm's text (the caller withdraws the bounds) or "". It needs the
    observer's covariance (a Kalman table, or any family given a noise model): the innovations
    carry the estimate's error ``C e`` as well as the noise, and only the covariance says how large
    it is (fixed gains without one: their transients, after a start or each unseen stretch of a
    channel, are many times the noise and alarmed at once). Without one the test is off
    (``bias_off`` says why).
``after(t, channel, rows, y, valid)``
    once the sample is taken: while the caller's bounds are withdrawn (``valid`` False), the
    sample joins the window of :mod:`switchobs_core.runtime.recertify` (cleared at the withdrawal,
    at every alarm and when time goes back, i.e. a reset); as soon as the window certifies a
    bound, the observer's rigorous bounds restart from it (and the estimate from the fit ``x_ls``
    when it is off by more than three of the fit's standard deviations for noise of std ``v_max``:
    the filter's covariance no longer describes its error then, e.g. after a sensor fault it
    followed, and the bias test would keep alarming on its transient)
    (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.recertify`) and the
    :class:`~switchobs_core.runtime.recertify.Certificate` is returned: the caller publishes the
    bounds again, labelled re-certified since ``certificate.t``.
``rejected(t, channel, rows, y)`` / ``accepted(channel)``
    the chi-square gate's verdicts: ``starve`` consecutive rejections of one channel are a model
    failure of the body only that channel sees (the states that no other channel observes), not
    outliers: the text says so and, with ``reinit``, that body's states are re-initialised by a
    least-squares fit to its last samples (position, and velocity from two or more samples,
    the other states held at the estimate) through
    :meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate` (the caller withdraws
    the bounds: re-certification brings them back).

Re-certification needs a declared ``noise_max`` (the radius is in its units) and the rigorous
bounds (innovation hold); without them ``after`` never certifies. A noise-free declaration
(``noise_max`` 0 for every channel, exact stamps, no declared disturbance) certifies too: a window is read with the
allowance ``|v_j| <= NOISE_FREE ||y||_inf`` per sample (:data:`NOISE_FREE`, a rounding level),
which holds wherever the declaration does (0 is within it), so a window whose residual is at the
rounding level certifies a radius at that level, and one with more is refused.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..numerics.disturbance_reach import DisturbanceReach
from ..numerics.rounding import gamma
from .bias import K_REF, BiasDetector, H, unit_normalised
from .consistency import block_product, is_unit, output_rows, seen_columns
from .recertify import Certificate, DataWindow

__all__ = ["Recovery", "body_states", "cycle_span"]

#: Consecutive gate rejections of one channel that make a model failure (not outliers).
STARVE = 25
#: The noise allowance of a window under a noise-free declaration, relative to each sample's largest
#: entry: far above the rounding of a simulated plant over a window (thousands of steps of ~1e-16),
#: far below any noise a sensor has.
NOISE_FREE = 2.0**-30
#: The smallest entry the allowance is taken relative to (a sample of zeros).
NOISE_FLOOR = 1e-150


def cycle_span(observer: Any) -> float:
    """One full switching cycle of the observer's schedule (s): its longest designed cycle, or
    ``N h_max`` in robust mode."""
    taus = [float(d.cycle.tau) for d in observer.designs if getattr(d, "cycle", None) is not None]
    if taus:
        return max(taus)
    return float(observer.N * observer.bounds[1])


def body_states(A: np.ndarray, C: tuple[np.ndarray, ...], channel: int) -> list[int]:
    """The states only ``channel`` observes: nonzero columns of its observability matrix that are
    zero in every other channel's (for the paper's system: the agent that channel looks at)."""
    def seen(Ci: np.ndarray) -> np.ndarray:
        M, blocks = Ci, []
        for _ in range(A.shape[0]):
            blocks.append(M)
            M = M @ A
        return np.abs(np.vstack(blocks)).sum(axis=0) > 0
    mine = seen(C[channel - 1])
    other = np.zeros_like(mine)
    for i, Ci in enumerate(C):
        if i != channel - 1:
            other |= seen(Ci)
    return [int(j) for j in np.flatnonzero(mine & ~other)]


#: Resolution (s) to which a sample's age in the window is rounded up for the disturbance's reach.
REACH_STEP = 1e-3


def window_disturbance(observer: Any) -> Any:
    """The :class:`~switchobs_core.runtime.recertify.DataWindow` hook of a declared disturbance
    (None when none is active): ``(t_i - t, rows) -> b`` with ``b >= |C_row d| / v_max`` for every
    row of every channel, ``d`` what the disturbance moved the state between ``t_i`` and the
    window's time ``t``: the state at ``t_i`` is ``e^{A (t_i - t)} x(t) - int_0^tau e^{-A u} B_w
    w(t_i + u) du`` with ``tau = t - t_i``, whose norm is at most the reach of ``(-A, B_w)`` over
    ``tau`` (:class:`~switchobs_core.numerics.disturbance_reach.DisturbanceReach`, rounding
    included). ``tau`` is rounded up to :data:`REACH_STEP` (the reach grows with ``tau``: ``w = 0``
    after ``tau`` is allowed), which bounds the reach's cache."""
    dist = getattr(observer, "disturbance", None)
    if dist is None or not dist.active:
        return None
    reach = DisturbanceReach(-observer.A, dist.B_w, dist.w_max)
    row = 0.0
    for Ci, v in zip(observer.C, observer.noise_max):
        norms = np.sqrt(np.sum(Ci * Ci, axis=1)) * (1.0 + gamma(Ci.shape[1] + 1))
        row = max(row, float(np.max(norms, initial=0.0)) / v if v > 0 else np.inf)
    row *= 1.0 + 4 * np.finfo(float).eps

    def bound(dt: float, rows: int) -> float:
        tau = np.ceil(max(-dt, 0.0) / REACH_STEP) * REACH_STEP
        return row * reach.radius(float(tau)) * (1.0 + 4 * np.finfo(float).eps)
    return bound


class Recovery:
    """The recovery of the module docstring for ``observer``.

    Parameters
    ----------
    observer : SwitchedObserver
    recertify, bias, reinit : bool
        Re-certification from data, the CUSUM bias test, the re-initialisation of a starved body.
    span : float, optional
        Seconds of data a window must hold (default: one switching cycle, :func:`cycle_span`).
    k_ref, h : float
        The CUSUM's reference value and threshold (:mod:`switchobs_core.runtime.bias`).
    starve : int
        Consecutive gate rejections of a channel that make a model failure.
    labels : sequence of sequences of str, optional
        Output labels per channel (the alarms name the row).
    """

    def __init__(self, observer: Any, *, recertify: bool = True, bias: bool = True, reinit: bool = True,
                 span: float | None = None, k_ref: float = K_REF, h: float = H, starve: int = STARVE,
                 labels: Any = None) -> None:
        self.obs = observer
        self.C = observer.C
        self.N = observer.N
        vmax = observer.noise_max
        self.vmax = None if vmax is None else tuple(float(v) for v in vmax)
        dist = getattr(observer, "disturbance", None)
        self.noise_free = self.vmax is not None and all(v == 0 for v in self.vmax) \
            and not (dist is not None and dist.active)     # a disturbance's image needs a noise scale
        can = recertify and self.vmax is not None and (all(v > 0 for v in self.vmax) or self.noise_free)
        self.window = (DataWindow(observer.A, cycle_span(observer) if span is None else span, keep=1.0,
                                  disturbance=window_disturbance(observer)) if can else None)
        #: Why the bias test is off although asked for ("" when it runs or was not asked for).
        self.bias_off = ("no covariance of the estimate (give the observer a noise model): the innovations' "
                         "spread is unknown" if bias and getattr(observer, "P", None) is None else "")
        self.bias = BiasDetector(observer.p, k_ref, h) if bias and not self.bias_off else None
        self.reinit = bool(reinit)
        self.starve = int(starve)
        self.labels = labels
        self.certificate: Certificate | None = None     # the latest re-certification
        self.recertifications = 0
        self.reinits = 0
        self.restarts = 0       # re-certifications that also restarted the estimate from the fit
        self.last_alarm = ""
        self.last_starved = ""
        self._valid = True
        self._run = [0] * self.N
        self._raw: list[deque] = [deque(maxlen=5) for _ in range(self.N)]
        #: (channel, rows) -> the bias test's C_r, its seen_columns, C_r on them, noise, R, is_unit of C_r on them
        self._rows: dict = {}

    # ------------------------------------------------------------------ the bias test
    def before(self, t: float, channel: int, rows: Any, y: np.ndarray, x_p: np.ndarray | None = None,
               nu: np.ndarray | None = None, *, quiet: bool = False) -> str:
        """The CUSUM on the sample's normalised innovations (module docstring); "" or the alarm. ``x_p``:
        the observer's held prediction at ``t`` (``predict(t, hold=True)``, as its ``prior`` gives it) when
        the caller has it, else it is asked for; ``nu``: the innovation ``y - C_r x_p`` when the caller
        computed it with the same ``C_r`` (the same doubles), else it is computed here. ``quiet``: the caller
        holds ``np.errstate(all="ignore")`` (the screening's), so none is set up here."""
        if self.bias is None:
            return ""
        obs = self.obs
        key = (channel, None if rows is None else tuple(rows))
        noise = obs.noise
        hit = self._rows.get(key)
        if hit is None or hit[3] is not noise:
            C_r = output_rows(self.C[channel - 1], rows)
            cols = seen_columns(C_r)
            Cc = C_r if cols is None else C_r[:, cols]
            R = None if noise is None else noise.R(channel, rows)
            hit = self._rows[key] = (C_r, cols, Cc, noise, R, cols is not None and is_unit(Cc),
                                     None if R is None else np.diagonal(R).tolist())
        if quiet:
            s = self._normalised(t, channel, y, x_p, nu, hit)
        else:
            with np.errstate(all="ignore"):
                s = self._normalised(t, channel, y, x_p, nu, hit)
        if s is None:
            return ""
        alarm = self.bias.update(channel, rows, s)
        if alarm is None:
            return ""
        row = alarm.row
        label = ""
        if self.labels is not None:
            label = str(self.labels[channel - 1][row])
        self.last_alarm = f"at t = {t:.6g} s: " + alarm.describe(label)
        if self._valid:     # a withdrawal: the window starts here (while withdrawn, the window's own
            self.withdrawn()    # residual test judges its data: the filter's transient alarms too)
        return alarm.describe(label)

    def _normalised(self, t: float, channel: int, y: np.ndarray, x_p: np.ndarray | None, nu: np.ndarray | None,
                    hit: tuple) -> Any:
        """The bias test's normalised innovations (``hit``: the rows' entry of :attr:`_rows`), or None when
        there is no covariance or a spread is 0 (the update ignores such a sample). Runs under an error
        state that ignores overflow (the caller's)."""
        obs = self.obs
        C_r, cols, Cc, noise, R, unit, r_diag = hit
        if nu is None:
            nu = np.asarray(y, dtype=float) - C_r @ (obs.predict(t, hold=True) if x_p is None else x_p)
        P = obs.prior_covariance(t, cols)       # the block on the states the rows see (rows_product)
        if P is None or noise is None:
            return None
        if unit and math.isfinite(float(P.sum())):
            return unit_normalised(nu, P, r_diag, None if self.vmax is None else self.vmax[channel - 1])
        S = block_product(Cc, P, unit) + R
        sd = np.sqrt(np.maximum(np.diagonal(S), 0.0))
        if self.vmax is not None:   # a noise model tighter than the declared bound: the bound's
            sd = np.maximum(sd, self.vmax[channel - 1] / 3.0)       # 3 sigma is the spread
        return nu / sd

    # ------------------------------------------------------------------ re-certification
    def withdrawn(self) -> None:
        """The bounds were withdrawn (or an alarm fired): the window starts again."""
        if self.window is not None:
            self.window.clear()
        self._valid = False

    def after(self, t: float, channel: int, rows: Any, y: np.ndarray, valid: bool) -> Certificate | None:
        """The sample the observer took at ``t`` (its time now); ``valid``: whether the caller
        publishes the bounds. Returns the certificate when the bounds were re-certified now."""
        w = self.window
        if w is None:
            return None
        if w.t is not None and t < w.t:         # a reset: another time origin
            w.clear()
        if valid:
            if not self._valid:
                w.clear()
            self._valid = True
            return None
        if self._valid:                          # withdrawn since the last sample
            w.clear()
            self._valid = False
        w.add(t, output_rows(self.C[channel - 1], rows), y, self._allowance(y, channel), channel)
        w.clock = float(getattr(getattr(self.obs, "rounding", None), "tolerance", 0.0) or 0.0)
        cert = w.certificate(range(1, self.N + 1))
        if cert is None:
            return None
        obs = self.obs
        if cert.variances is not None and cert.bound(obs.x_hat) - cert.radius > 3.0 * np.sqrt(cert.variances.sum()):
            # the estimate is off by more than three of the fit's standard deviations: take the fit
            var = dict(enumerate(cert.variances.tolist())) if obs.P is not None else None
            obs.set_estimate(t, dict(enumerate(cert.x_ls.tolist())), var)
            self.restarts += 1
        if not obs.recertify(cert.bound(obs.x_hat)):
            return None
        self.certificate = cert
        self.recertifications += 1
        w.clear()
        self._valid = True
        if self.bias is not None:
            self.bias.reset()
        return cert

    def _allowance(self, y: np.ndarray, channel: int) -> float:
        """The noise allowance of a sample of ``channel`` in the window: the declared bound, or under a
        noise-free declaration :data:`NOISE_FREE` times its largest entry (inf with a declared stamp
        error, which a noise-free window does not carry: no certificate)."""
        if not self.noise_free:
            return self.vmax[channel - 1]
        if getattr(getattr(self.obs, "rounding", None), "tolerance", 0.0):
            return math.inf
        return NOISE_FREE * max(float(np.max(np.abs(y), initial=0.0)), NOISE_FLOOR)

    # ------------------------------------------------------------------ a starved body
    def accepted(self, channel: int) -> None:
        """The gate passed a sample of ``channel``."""
        self._run[channel - 1] = 0
        self._raw[channel - 1].clear()

    def rejected(self, t: float, channel: int, rows: Any, y: np.ndarray) -> str:
        """The gate rejected a sample of ``channel`` at ``t``: "" or, at the ``starve``-th in a row,
        the model failure's text (the body's states re-initialised when ``reinit``)."""
        i = channel - 1
        self._run[i] += 1
        self._raw[i].append((float(t), None if rows is None else list(rows), np.array(y, dtype=float)))
        if self._run[i] < self.starve:
            return ""
        self._run[i] = 0
        states = body_states(self.obs.A, self.C, channel)
        names = f"the body only channel {channel} sees"
        why = (f"the chi-square gate rejected {self.starve} consecutive samples of channel {channel}: a model failure "
               f"of {names} (it does not move as A says), not outliers")
        if self.reinit and states and self._reinit(t, channel, states):
            self.reinits += 1
            why += f"; its states {states} re-initialised from its last {len(self._raw[i])} samples"
        self._raw[i].clear()
        self.last_starved = f"at t = {t:.6g} s: {why}"
        self.withdrawn()
        return why

    def _reinit(self, t: float, channel: int, states: list[int]) -> bool:
        """Least squares on the channel's last samples for ``states``, the others held at the
        estimate propagated open loop; ``set_estimate`` at ``t``. False when they do not fix them."""
        obs = self.obs
        if t < obs.t:
            return False
        x_t = obs.predict(t)
        other = np.ones(obs.n, dtype=bool)
        other[states] = False
        rows_M, rhs = [], []
        for ti, rows, yi in self._raw[channel - 1]:
            O = output_rows(self.C[channel - 1], rows) @ expm(obs.A * (ti - t))
            rows_M.append(O[:, states])
            rhs.append(yi - O[:, other] @ x_t[other])
        M, b = np.vstack(rows_M), np.concatenate(rhs)
        if np.linalg.matrix_rank(M) < len(states):
            return False
        xb = np.linalg.lstsq(M, b, rcond=None)[0]
        if not np.all(np.isfinite(xb)):
            return False
        var = None
        if obs.P is not None and obs.noise is not None:
            sd2 = float(np.max(np.diagonal(obs.noise.R(channel, None))))
            var = dict(zip(states, (sd2 * np.diagonal(np.linalg.pinv(M.T @ M))).tolist()))
        obs.set_estimate(t, dict(zip(states, xb.tolist())), var)
        if self.bias is not None:
            self.bias.reset()
        return True
