"""A bound on the observer's error certified from a window of data (re-certification).

Over one full switching cycle all channels together are observable (e:outputs), so a window of
samples ``y_i = C_{r_i} x(t_i) + v_i`` (``|v_ij| <= v_max`` of the sample's channel) with a
plant that follows ``x' = A x`` (e:system) determines the state at the window's last time ``t``:

.. math::

    y_i = C_{r_i} e^{A (t_i - t)} x(t) + v_i =: O_i x(t) + v_i .

Weighted by ``w_i = 1 / v_max`` the stacked rows give ``y_w = R x(t) + v_w`` with ``||v_w|| <= sqrt(m)``
(``m`` rows). For any ``x_c`` (the computed least-squares fit), with ``z = x(t) - x_c`` and ``R`` of full
column rank, ``z = R^+ (y_w - R x_c) - R^+ v_w``, so

.. math::

    \\|x(t) - x_c\\| \\le \\frac{\\|R^\\top r\\|}{\\sigma_{min}(R)^2} + \\frac{\\sqrt{m}}{\\sigma_{min}(R)},
    \\qquad r = y_w - R x_c ,

an a posteriori bound: it needs no bound on how well ``x_c`` was solved for, only a certified
lower bound of ``sigma_min`` and the residual with its rounding. Rounding is included throughout
(:mod:`switchobs_core.numerics.rounding`): the rows are kept at the window's latest time by
stepping them back with ``e^{-A dt}`` from :func:`~switchobs_core.numerics.expm_bound.certify_zoh`
(a proven error ``dE``), each row carrying a bound ``delta_i`` of its distance to the exact row;
``sigma_min`` is bounded below by the eigenvalue of ``fl(R' R)`` less its product's, the
solver's and the rows' errors; the residual, ``R' r`` and the weights' rounding get their
``gamma_n`` allowances. The derivation with the exact rows ``R_t`` (``||R - R_t||_2 <= Delta =
||delta||``, ``s = sigma_min(R_t) >= sigma_lo(R) - Delta``):

.. math::

    \\|z\\| \\le \\frac{\\|R^\\top r\\| + \\Delta \\|r\\|}{s^2}
          + \\frac{\\Delta \\|x_c\\| + \\sqrt{m} + \\epsilon_y + d_w}{s}

where ``epsilon_y`` is the weighted data's rounding and ``d_w`` the hook for a declared bounded
disturbance (the norm of its weighted image over the window; 0 when none is declared).

A declared clock tolerance ``d`` (:attr:`DataWindow.clock`: every sample was taken at ``t_i +
delta_i``, ``|delta_i| <= d``, not at its stamp ``t_i``) adds to each weighted row the error
``R_i (e^{A delta_i} - I) x(t)`` (the exact row commutes with ``e^{A delta_i}``). With
``e^{A delta} - I = A delta + E_2``, ``||E_2|| <= c_2 = e^{nu(A) d} - 1 - nu(A) d``, and ``x(t) = x_c +
z``, it is at most ``a_i + b_i ||z||``:

.. math::

    a_i = d |R_i A x_c| + (d \\delta_i \\nu + (\\|R_i\\| + \\delta_i) c_2) \\|x_c\\|, \\qquad
    b_i = d (\\|R_i A\\| + \\delta_i \\nu) + (\\|R_i\\| + \\delta_i) c_2

(``delta_i`` the row's distance to the exact row, the products' rounding added to ``a_i`` and
``||R_i A||``). So the bound above gains ``(||a|| + ||b|| ||z||) / s`` and, solved for ``||z||``
(``||b|| < s``),

.. math::

    \\|z\\| \\le \\frac{\\rho_0 + \\|a\\| / s}{1 - \\|b\\| / s}

with ``rho_0`` the bound without it. ``a`` is first order in ``d`` times the state's rate seen by
each row (``R_i A x_c``), so a body at rest costs little. A window whose rows a clock error of ``d``
could move by as much as they fix the state (``||b|| >= s``) certifies nothing. The residual and
row-by-row tests allow the same term. A constant offset of every stamp is invisible in the data
(the samples of ``x(t + delta)`` fit the model exactly): only this term covers it. The
observer's error at ``t`` is then at most ``||x_hat(t) - x_c|| + ||z||``: a ball that the observer's
rigorous ellipsoids restart from (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.recertify`)
and propagate with their usual steps.

What it assumes: the model held over the whole window (the plant followed ``x' = A x`` plus any
declared disturbance, every sample's noise within ``noise_max``, the channel of every sample
right). Data cannot prove that, only refute it: a window whose least residual exceeds what
any noise within the bound allows (``||r|| > sqrt(m)``, allowances included) is refused, and so
is one that no state explains row by row (:func:`chebyshev`: every row within its own allowance
``1 + epsilon_y,i + d_w,i + delta_i (||x_c|| + radius)``, the sharp test: a body that accelerated
while the window saw it for part of its span bends its own rows away from every path of the
model, which the norm over the whole window averages out); a window is cleared whenever a test
alarms (:mod:`switchobs_core.runtime.recovery`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..numerics.expm_bound import certify_zoh, nu
from ..numerics.frobenius import underflow_slack
from ..numerics.rounding import UNDERFLOW, UNIT_ROUNDOFF, gamma

__all__ = ["Certificate", "DataWindow", "chebyshev"]

_U = UNIT_ROUNDOFF
_UP = 1.0 + 8.0 * _U


def _norm(v: np.ndarray) -> float:
    """``||v||_2`` rounded up (a sum of squares and a square root: relative ``gamma_{k+2}``) plus what
    underflow hides from it (:func:`~switchobs_core.numerics.frobenius.underflow_slack`)."""
    return math.sqrt(float(v.ravel() @ v.ravel())) * (1.0 + gamma(v.size + 2)) + underflow_slack(v.size)


@dataclass(frozen=True)
class Certificate:
    """``||x(t) - x_ls|| <= radius`` from the window ``[t_start, t]`` of ``rows`` weighted rows
    (``samples`` samples); ``sigma`` the certified lower bound of ``sigma_min`` of the rows."""

    t: float
    t_start: float
    x_ls: np.ndarray
    radius: float
    sigma: float
    rows: int
    samples: int
    variances: np.ndarray | None = None     # diag((R' R)^-1): the fit's variances for noise of std v_max

    def __post_init__(self) -> None:
        if self.variances is not None and not np.all(np.isfinite(self.variances)):
            object.__setattr__(self, "variances", None)

    def bound(self, x_hat: np.ndarray) -> float:
        """``>= ||x(t) - x_hat||``: ``||x_hat - x_ls||`` rounded up plus the radius."""
        d = np.asarray(x_hat, dtype=float) - self.x_ls
        rnd = _U * (_norm(np.asarray(x_hat, dtype=float)) + _norm(self.x_ls))
        return (_norm(d) + rnd + self.radius) * _UP


#: Share of the span after a window the row-by-row test refused during which no certificate is
#: tried (the window then holds mostly the same data; each try is a linear program).
HOLD_SHARE = 0.05

#: Relative slack of the row-by-row test over the linear program's tolerances (a refusal is never
#: unsound; the slack keeps a window the data fit from being refused by the solver's rounding).
CHEBYSHEV_SLACK = 1e-6


def chebyshev(R: np.ndarray, r: np.ndarray, tol: np.ndarray) -> float:
    """``min_z max_i |r_i - R_i z| / tol_i``: the least share of its allowance ``tol_i`` the worst
    row needs when the fit moves by any ``z`` (``r = y - R x_c``: the rows' residuals at the fit).
    At most 1 iff some state explains every row within its allowance (infinity-norm
    consistency). ``max |r_i| / tol_i`` when that is at most 1 (``z = 0``); else the linear
    program ``min s`` subject to ``|r - R z| <= s tol`` (HiGHS); ``inf`` when it fails."""
    q = np.abs(r) / tol
    if not q.size or float(np.max(q)) <= 1.0:
        return float(np.max(q, initial=0.0))
    m, n = R.shape
    scale = np.maximum(np.max(np.abs(R), axis=0), np.finfo(float).tiny)     # columns of unit size
    Rs = R / scale
    col = -tol[:, None]
    A_ub = np.block([[-Rs, col], [Rs, col]])
    b_ub = np.concatenate([-r, r])
    cost = np.zeros(n + 1)
    cost[-1] = 1.0
    from scipy.optimize import linprog  # only a re-certification needs it: not imported at start-up

    res = linprog(cost, A_ub=A_ub, b_ub=b_ub, bounds=[(None, None)] * n + [(0.0, None)], method="highs")
    if res.status != 0 or res.x is None:
        return math.inf
    z = res.x[:n]
    return float(np.max(np.abs(r - Rs @ z) / tol))


class DataWindow:
    """The weighted rows of the recent samples, kept at the latest sample's time (module docstring).

    ``w = DataWindow(A, span)``; ``w.add(t, C_rows, y, v_max, channel)`` per sample (in time
    order), ``w.certificate(channels)`` when at least ``span`` seconds of data from every channel
    in ``channels`` are held (None otherwise, or when the rows are not yet of full rank, or the
    window is refused); ``w.clear()`` after any alarm. Samples older than ``keep * span`` are
    dropped. ``disturbance`` (optional): ``(t_i - t, rows) -> bound`` of the weighted disturbance
    image of a row block, summed in quadrature into ``d_w`` (the hook of the module docstring).
    ``clock``: the declared clock tolerance ``d`` in seconds (module docstring; 0: exact stamps),
    read at each :meth:`certificate`; with a declared disturbance too, no certificate is given.
    """

    def __init__(self, A: np.ndarray, span: float, *, keep: float = 1.25, cache: int = 64,
                 disturbance: Callable[[float, int], float] | None = None) -> None:
        self.A = np.asarray(A, dtype=float)
        self.n = self.A.shape[0]
        self.span = float(span)
        self.keep = float(keep)
        self.disturbance = disturbance
        self.clock = 0.0
        self._nA = nu(self.A)
        self._cache: dict[int, tuple[np.ndarray, float, float]] = {}
        self._cache_size = int(cache)
        self.refused = 0        # windows refused by the residual test
        self.last_refusal = ""
        self.hold = self.span * HOLD_SHARE
        self.clear()

    def clear(self) -> None:
        """Forget every sample."""
        self.R = np.zeros((0, self.n))
        self.y = np.zeros(0)
        self.delta = np.zeros(0)        # per row: ||row - exact row||_2
        self.ey = np.zeros(0)           # per row: |fl(w y) - w y|
        self.t_row = np.zeros(0)        # per row: its sample's time
        self.ch_row = np.zeros(0, dtype=int)
        self.t: float | None = None
        self._quiet_until = -math.inf

    def __len__(self) -> int:
        return int(self.y.size)

    @property
    def t_start(self) -> float | None:
        """The oldest sample's time (None when empty)."""
        return float(self.t_row[0]) if self.t_row.size else None

    def _back(self, dt: float) -> tuple[np.ndarray, float, float]:
        """``(E, dE, nu(E))``: ``E ~ e^{-A dt}`` with ``||E - e^{-A dt}||_2 <= dE``, cached per ns: an
        entry computed at ``dt_c`` serves ``dt`` with the step quantum
        ``||e^{-A dt} - e^{-A dt_c}|| <= (nu(E) + dE) (e^{nu(A) q} - 1)``, ``q = |dt - dt_c| + u dt`` (the
        computed difference of two times is within ``u dt`` of the true one)."""
        key = int(round(dt * 1e9))
        hit = self._cache.get(key)
        if hit is None:
            step = certify_zoh(-self.A, dt)
            hit = (dt, step.E, float(step.dE), nu(step.E))
            if len(self._cache) >= self._cache_size:
                self._cache.clear()
            self._cache[key] = hit
        dt_c, E, dE, nE = hit
        q = abs(dt - dt_c) + _U * dt
        dE = (dE + (nE + dE) * math.expm1(self._nA * q) * _UP) * _UP
        return E, dE, nE

    def add(self, t: float, C_rows: np.ndarray, y: np.ndarray, v_max: float, channel: int) -> None:
        """A sample ``y = C_rows x(t) + v`` with ``|v_j| <= v_max`` (``t`` not before the last one)."""
        t = float(t)
        if self.t is not None and t > self.t:
            dt = t - self.t
            E, dE, nE = self._back(dt)
            # rows at the new time: R e^{-A dt}; per row (||R_i|| the row's norm):
            # delta' = delta (nu(E) + dE) + ||R_i|| dE + gamma_n ||R_i|| nu(E)
            rn = np.sqrt(np.einsum("ij,ij->i", self.R, self.R)) * (1.0 + gamma(self.n + 2))
            self.R = self.R @ E
            self.delta = (self.delta * (nE + dE) + rn * (dE + gamma(self.n) * nE)) * _UP
        self.t = t
        C_rows = np.asarray(C_rows, dtype=float)
        y = np.asarray(y, dtype=float)
        w = 1.0 / float(v_max)
        Cw, yw = C_rows * w, y * w
        # fl(C w) and fl(y w): relative u each (w itself rounded: another u; 1/v_max >= the true one
        # would only shrink the weighted noise, so the allowance covers both directions)
        dC = 2.0 * _U * np.sqrt(np.einsum("ij,ij->i", Cw, Cw)) * _UP
        self.R = np.vstack([self.R, Cw])
        self.y = np.concatenate([self.y, yw])
        self.delta = np.concatenate([self.delta, dC])
        self.ey = np.concatenate([self.ey, 2.0 * _U * np.abs(yw) + UNDERFLOW])
        self.t_row = np.concatenate([self.t_row, np.full(y.size, t)])
        self.ch_row = np.concatenate([self.ch_row, np.full(y.size, int(channel))])
        keep = self.t_row >= t - self.keep * self.span * (1.0 + 1e-9)
        if not keep.all():
            self.R, self.y, self.delta = self.R[keep], self.y[keep], self.delta[keep]
            self.ey, self.t_row, self.ch_row = self.ey[keep], self.t_row[keep], self.ch_row[keep]

    def _clock_rows(self, R: np.ndarray, x_c: np.ndarray, xn: float) -> tuple[np.ndarray, np.ndarray]:
        """``(a, b)`` of the module docstring (zeros when no clock tolerance is declared): the
        weighted stamp error of row ``i`` is at most ``a_i + b_i ||x(t) - x_c||``, rounding included."""
        m = R.shape[0]
        if not self.clock:
            return np.zeros(m), np.zeros(m)
        d, nA = float(self.clock), self._nA
        c2 = max(math.expm1(nA * d * _UP) - nA * d, 0.0) * _UP + 4.0 * _U * nA * d
        absA = np.abs(self.A)
        RA = R @ self.A
        # |fl(fl(R A) x_c) - R A x_c| <= gamma_{2n} |R| |A| |x_c|; ||fl(R A)_i - (R A)_i|| <= gamma_n ||R_i|| nu
        g = gamma(2 * self.n + 2)
        rax = np.abs(RA @ x_c) + g * (np.abs(R) @ (absA @ np.abs(x_c)))
        rows = np.sqrt(np.einsum("ij,ij->i", R, R)) * (1.0 + gamma(self.n + 2))
        ra = np.sqrt(np.einsum("ij,ij->i", RA, RA)) * (1.0 + gamma(self.n + 2)) + gamma(self.n) * rows * nA
        a = (d * rax + (d * self.delta * nA + (rows + self.delta) * c2) * xn) * _UP * _UP
        b = (d * (ra + self.delta * nA) + (rows + self.delta) * c2) * _UP * _UP
        return a, b

    def ready(self, channels: Sequence[int]) -> bool:
        """Whether the window spans ``span`` seconds and holds a sample of every channel in ``channels``."""
        if self.t is None or not self.t_row.size or self.t - self.t_row[0] < self.span * (1.0 - 1e-9):
            return False
        return all(bool((self.ch_row == c).any()) for c in channels)

    def certificate(self, channels: Sequence[int]) -> Certificate | None:
        """The certificate of the module docstring (None: not :meth:`ready`, not of full rank, or
        refused by the residual test, counted in ``refused`` with ``last_refusal``)."""
        if not self.ready(channels) or self.t < self._quiet_until:
            return None
        if self.clock and self.disturbance is not None:
            self.last_refusal = ("a declared clock tolerance with a declared disturbance: the window's stamp "
                                 "errors are not bounded with the disturbance's reach (no certificate)")
            return None
        R, yw = self.R, self.y
        m, n = R.shape
        if m < n:
            return None
        with np.errstate(all="ignore"):
            x_c = np.linalg.lstsq(R, yw, rcond=None)[0]
            if not np.all(np.isfinite(x_c)):
                return None
            # sigma_min(R) from fl(R' R): its product's error gamma_m ||R||_F^2, the solver's 2 n u ||G||_F
            G = R.T @ R
            G = 0.5 * (G + G.T)
            fR2 = float(np.einsum("ij,ij->", R, R)) * (1.0 + gamma(m * n + 2))
            fG = _norm(G)
            try:
                lam = float(np.linalg.eigvalsh(G)[0])
            except np.linalg.LinAlgError:
                return None
            lam_lo = (lam - gamma(m + 2) * fR2 - 2 * n * _U * fG - 4 * n * UNDERFLOW) / _UP
            Delta = _norm(self.delta)
            if not (math.isfinite(lam_lo) and lam_lo > 0.0):
                return None
            s = math.sqrt(lam_lo) / _UP - Delta
            if not s > 0.0:
                return None
            r = yw - R @ x_c
            # |fl(y - R x) - (y - R x)| <= gamma_{n+1} (|R| |x| + |y|)
            er = _norm(gamma(n + 1) * (np.abs(R) @ np.abs(x_c) + np.abs(yw))) * _UP
            rn = _norm(r)
            Rtr = R.T @ r
            Rtr_n = _norm(Rtr) + gamma(m + 2) * math.sqrt(fR2) * rn + math.sqrt(fR2) * er
            ey = _norm(self.ey)
            dws = np.zeros(m)
            if self.disturbance is not None:
                dws = np.array([self.disturbance(float(ti - self.t), 1) for ti in self.t_row])
            dw = _norm(dws)
            xn = _norm(x_c)
            root_m = math.sqrt(m) * _UP
            radius = ((Rtr_n + Delta * (rn + er)) / (s * s) + (Delta * xn + root_m + ey + dw) / s) * _UP * _UP
            a, b = self._clock_rows(R, x_c, xn)
            na, nb = (_norm(a), _norm(b)) if self.clock else (0.0, 0.0)      # no clock: no stamp error
            if nb:
                q = nb / s * _UP
                if not q < 1.0:
                    self.last_refusal = (f"window [{self.t_row[0]:.6g}, {self.t:.6g}] s: a stamp error of the declared "
                                         f"clock tolerance moves its rows as much as they fix the state ({q:.3g})")
                    return None
                radius = (radius + na / s * _UP) / ((1.0 - q) / _UP) * _UP
            clock = (na + nb * radius) * _UP
            # the window's data against the model: the least weighted residual is at most ||v_w|| (and
            # the stamps' errors)
            least = (rn - er - Delta * xn) / _UP
            if least > root_m + ey + dw + clock:
                self.refused += 1
                self.last_refusal = (f"window [{self.t_row[0]:.6g}, {self.t:.6g}] s refused: weighted residual "
                                     f"{least:.4g} > {root_m + ey + dw + clock:.4g} (the data do not fit the model "
                                     "within noise_max)")
                return None
            # the same row by row (the sharp test): some state must explain every row within its own
            # allowance; a drift the norm over the window averages out (a manoeuvre seen for part of
            # the window) does not fit any
            tol = (1.0 + self.ey + dws + self.delta * (xn + radius) + a + b * radius) * _UP
            worst = chebyshev(R, r, tol)
            if worst > 1.0 + CHEBYSHEV_SLACK:
                self.refused += 1
                self._quiet_until = self.t + self.hold
                self.last_refusal = (f"window [{self.t_row[0]:.6g}, {self.t:.6g}] s refused: no state explains every "
                                     f"sample within noise_max (the least worst row uses {worst:.4g} of its "
                                     "allowance)")
                return None
        if not math.isfinite(radius):
            return None
        try:
            var = np.maximum(np.diagonal(np.linalg.inv(G)), 0.0)
        except np.linalg.LinAlgError:
            var = None
        return Certificate(float(self.t), float(self.t_row[0]), x_c, float(radius), float(s), int(m),
                           int(np.unique(self.t_row).size), var)
