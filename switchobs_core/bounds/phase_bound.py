r"""The observer's rigorous bounds as scalars in a norm fixed per phase of a Kalman table: the
``bound="phase"`` option of :class:`~switchobs_core.runtime.observer.SwitchedObserver`.

On the periodic part of a Kalman table's grid every sample's error map is the phase's
``M_j = (I - K_j H_j) Phi~`` (:mod:`switchobs_core.bounds.kalman_map`), so the ellipsoids of
:class:`~switchobs_core.bounds.rigorous.RoundingBound` can be replaced by scalars in the norms
``||e||_{P_j}`` of :mod:`switchobs_core.bounds.phase_norm` (``P_j`` the discounted periodic Lyapunov
shapes, their constants proved in floating point). Per sample, with the same residual ``rho``
(balanced) as the ellipsoid's fused step (:meth:`~switchobs_core.bounds.rigorous.RoundingBound.fused`,
its ``||D^-1 e^-||`` read from the scalar: ``sqrt(b_{j-1}) beta``):

* the exact set: ``beta_k = c_j beta_{k-1} + h_j rho_k + g_j w`` (``w`` the stamp error of a
  declared clock tolerance, 0 without one);
* the noise set (a declared ``v_max``): ``beta_k = c_j beta_{k-1} + h_j rho_k + g_j (sqrt(p) v_max +
  w)``, with ``g_j >= ||P_j^-1/2 K_j||_2`` proved (``g_j^2 P_j >= K_j K_j'``);

each rounded up, and the published bound ``sqrt(t_j) beta`` (``t_j >= lambda_max(P_j)``). The
constants ``c_j`` are proved for the computed dense map ``E~_j = fl(fl(I - K H) Phi~)``, whose
distance to the exact ``(I - K H) Phi~`` (:attr:`PhaseBound.emap`, the dense form's
``gamma_{p+1} kappa nu(Phi~) + gamma_n nu(I - K H) nu(Phi~)``) joins the residual on either path.
A stamp off the grid by less than the table's ``dt_tol`` (still locked) has the phase's gain over
its own step, ``Phi~_a`` of another ZOH entry: its map is ``M_j + (I - K H) (Phi~_a - Phi~_d)``, so
``||I - K H|| nu(D^-1 (Phi~_a - Phi~_d) D) ||D^-1 e||`` (the computed difference, relative ``u`` per
entry, :meth:`PhaseBound._gap`) joins the residual, whose prediction part is that entry's own.

Entering and leaving (the option is sound wherever it is not on the periodic grid):

* the start-up phases, a departure and any other sample keep the ellipsoids;
* at a periodic sample, once the ellipsoid's step is taken, the ellipsoid ``S`` enters as ``beta =
  sqrt(a)`` with ``a P_j >= S`` proved (:func:`~switchobs_core.bounds.phase_norm.verified_factor`);
* the next sample that is not the next phase's (a missing sample, a departure), a restart or any
  other use of the ellipsoids first puts them back: ``S = fl(s P_j)`` with ``S >= beta^2 P_j``
  proved (``a S >= P_j`` with ``a <= 1 / beta^2``, :func:`~switchobs_core.bounds.phase_norm.dominates`),
  else the ball ``||e|| <= sqrt(t_j) beta``; a read at a later time and the innovation test's prior
  take norm bounds from the scalars (:meth:`PhaseBound.later`) instead.

A declared disturbance is not covered (the option refuses it).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..numerics.expm_bound import nu
from ..numerics.frobenius import underflow_slack
from ..numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid, gamma
from .phase_norm import PhaseNorms, dominates, lyapunov_shapes, verified_factor

__all__ = ["NOISE_FLOOR", "NOISE_SLACK", "PhaseBound", "SLACK", "dense_map_error", "driven_shapes"]

_U = UNIT_ROUNDOFF
#: ``lambda = 1 - SLACK (1 - r)`` of the shapes, ``r`` the period's per-step contraction.
SLACK = 0.5
#: Relative margins of ``S = fl(s P_j)`` over ``beta^2``, tried in turn when the ellipsoid is put back.
_BACK = (1e-9, 1e-6, 1e-3)
#: The noise set's shapes: ``D^2`` times this fraction of the gain's balanced trace joins ``K_j K_j'``.
NOISE_FLOOR = 1e-5
#: The noise set's ``lambda`` (its shapes' slack, as :data:`SLACK`): looser discounting fits the
#: noise's sum better (camera_agents(2): the bound 6.1x the ellipsoid's at 0.75, 8.0x at 0.5).
NOISE_SLACK = 0.75
#: Work (``N n^3``) above which the constants' computation prints a progress line.
_SLOW = 2e8


def driven_shapes(maps: Sequence[np.ndarray], drive: Callable[[int], np.ndarray], lam: float,
                  rounds: int = 4) -> list[np.ndarray]:
    """``P_j = M_j P_{j-1} M_j' / lam^2 + Q_j`` over the period (as
    :func:`~switchobs_core.bounds.phase_norm.lyapunov_shapes` with a drive ``Q_j = drive(j)`` per
    phase, formed when needed), each exactly symmetric."""
    P = [drive(j) for j in range(len(maps))]
    for _ in range(rounds):
        for j, Mj in enumerate(maps):
            Pj = (Mj @ P[j - 1]) @ Mj.T
            Pj /= lam * lam
            Pj += drive(j)
            P[j] = 0.5 * (Pj + Pj.T)
    return P


def _gain_factors(pn: PhaseNorms, maps: Sequence[Any]) -> np.ndarray:
    """``g_j >= ||P_j^-1/2 K_j||_2`` proved (``g_j^2 P_j >= K_j K_j'``), rounded up."""
    return np.array([math.sqrt(verified_factor(P, np.eye(m.K.shape[1]), m.K)) * (1.0 + 8.0 * _U)
                     for P, m in zip(pn.shapes, maps, strict=True)])


def _check(pn: PhaseNorms, g: np.ndarray) -> None:
    for name, v in (("c", pn.c), ("h", pn.h), ("t", pn.t), ("b", pn.b), ("g", g)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"the phase bound's constant {name}_j could not be proved for every phase")


def dense_map_error(m: Any) -> float:
    """``>= ||E~ - (I - K H) Phi~||_2`` (balanced) of the dense ``E~ = fl(fl(I - K H) Phi~)`` of a
    :class:`~switchobs_core.bounds.kalman_map.KalmanMap` (the formula of its dense path's ``emap``)."""
    d = m.e.scale
    ikh = m._I - m.K @ m.H
    nI = nu((ikh / d[:, None]) * d[None, :])
    nP = m.e.nPhi
    return (gamma(m.H.shape[0] + 1) * m.kappa * nP + gamma(m.Phi.shape[0]) * nI * nP) * (1.0 + 8.0 * gamma(1))


class PhaseBound:
    """The scalars of the module docstring for one Kalman table's periodic phases.

    ``PhaseBound(maps, scale, noisy)``: ``maps[j]`` the :class:`~switchobs_core.bounds.kalman_map.KalmanMap`
    of periodic phase ``j`` at the design's step (the family's own objects: a sample is on the
    option's path when its map *is* its phase's), ``scale`` the balancing ``D``, ``noisy`` whether a
    noise set is kept. Raises ValueError when a constant cannot be proved. ``progress`` receives a
    line when the computation is slow (default: standard error).

    State: :attr:`j` the phase of the last sample while the scalars hold (-1: the ellipsoids hold),
    :attr:`beta`, :attr:`betav`; counts :attr:`entered`, :attr:`left`.
    """

    def __init__(self, maps: Sequence[Any], scale: np.ndarray, noisy: bool, *, slack: float = SLACK,
                 progress: Callable[[str], None] | None = None) -> None:
        t0 = time.process_time()
        self.maps = list(maps)
        N, n = len(self.maps), self.maps[0].Phi.shape[0]
        say = progress or (lambda s: print(s, file=sys.stderr, flush=True))
        if N * n ** 3 > _SLOW:
            say(f"phase bound: proving the norms of {N} phases at n = {n} (a few seconds)")
        d = np.asarray(scale, dtype=float)
        Es = [m.dense() for m in self.maps]
        mono = np.eye(n)
        for j in range(1, N + 1):
            mono = Es[j % N] @ mono
        rate = float(np.max(np.abs(np.linalg.eigvals(mono)))) ** (1.0 / N)
        if not rate < 1.0:
            raise ValueError(f"the Kalman table's period does not contract (per-step rate {rate:.6g})")
        self.lam = 1.0 - slack * (1.0 - rate)
        self.lamv = 1.0 - NOISE_SLACK * (1.0 - rate)
        self.norms = pn = PhaseNorms(Es, lyapunov_shapes(Es, d, self.lam), d)
        self.g = _gain_factors(pn, self.maps)
        self.emap = np.array([dense_map_error(m) for m in self.maps])
        _check(pn, self.g)
        # the noise set: shapes driven by the gain's image (the noise's directions) and a little of D^2
        self.normsv, self.gv = pn, self.g
        if noisy:
            D2 = np.diag(d * d)

            def drive(j: int) -> np.ndarray:
                K = self.maps[j].K
                KK = K @ K.T
                Q = KK + (NOISE_FLOOR * max(float(np.trace(KK / np.outer(d, d))), 1e-300) / n) * D2
                return 0.5 * (Q + Q.T)

            self.normsv = PhaseNorms(Es, driven_shapes(Es, drive, self.lamv), d)
            self.gv = _gain_factors(self.normsv, self.maps)
            _check(self.normsv, self.gv)
        self.N, self.n, self.noisy = N, n, bool(noisy)
        self.seconds = time.process_time() - t0
        if N * n ** 3 > _SLOW:
            say(f"phase bound: {N} phases proved in {self.seconds:.1f} s CPU")
        self.entered = self.left = 0
        # per-sample reads as Python floats (a numpy scalar's arithmetic costs more)
        self._c, self._h, self._g, self._emap = (pn.c.tolist(), pn.h.tolist(), self.g.tolist(), self.emap.tolist())
        self._cv, self._hv, self._gv = self.normsv.c.tolist(), self.normsv.h.tolist(), self.gv.tolist()
        self._sb, self._sbv = pn._sqrt_b.tolist(), self.normsv._sqrt_b.tolist()
        self._st, self._stv = pn._sqrt_t.tolist(), self.normsv._sqrt_t.tolist()
        self.reset()

    def reset(self) -> None:
        """The ellipsoids hold (nothing entered)."""
        self.j = -1
        self.beta = self.betav = math.inf
        self._xlast: tuple = (None, 0.0)     # the last estimate and its balanced norm (the next x0's)
        self._nus: dict = {}
        self._gaps: dict = {}

    # ------------------------------------------------------------------ samples
    def sample(self, b: Any, f: Any, channel: int) -> bool:
        """Step the scalars through the fused map ``f`` (a :class:`~switchobs_core.runtime.error_maps.FusedMap`
        of periodic phase ``f.phase``, -1 for the start-up) of the bound ``b``; False when the sample is
        not the next phase's (the ellipsoids are put back first if the scalars held: the caller steps them)."""
        j = f.phase
        if self.j < 0:
            return False
        m, mj = f.m, self.maps[j if j >= 0 else 0]
        gap = 0.0
        if j != (self.j + 1) % self.N or m.K is not mj.K or m.H is not mj.H:
            self.leave(b)
            return False
        if m is not mj:     # the phase's gain over another step (a stamp off the grid within dt_tol)
            gap = self._gap(m.e, mj.e)
            if not math.isfinite(gap):
                self.leave(b)
                return False
            m = mj          # the same K, H and balancing: the same norms of the gain
        pj = self.j
        xl = self._xlast
        xs = xl[1] if f.x0 is xl[0] else b.xn(f.x0)
        y, nu_ = f.y, f.nu
        yn = math.sqrt(float(y @ y)) + underflow_slack(y.size)      # + what underflow hides (numerics.frobenius)
        xs1, nun = b.xn(f.x_minus), math.sqrt(float(nu_ @ nu_)) + underflow_slack(nu_.size)
        fK = m.fK
        # ||D^-1 x^+|| <= (||D^-1 x^-|| + (1 + gamma_p) ||D^-1 K||_F ||nu||) (1 + u), x^+ = fl(x^- + fl(K nu))
        xsp = (xs1 + fK * nun * (1.0 + b.g_p)) * (1.0 + 2.0 * _U)
        self._xlast = (f.x_plus, xsp)       # the next sample's ||D^-1 x0|| (an upper bound serves)
        rc = b.rho_correct_norms(fK, m.fH, xs1, yn, nun, xsp, y.size)
        en = self._sb[pj] * self.beta * (1.0 + 4.0 * _U)        # PhaseNorms.balanced
        env = self._sbv[pj] * self.betav * (1.0 + 4.0 * _U) if self.noisy else 0.0
        e, dt, nIKH, emap = f.m.e, f.dt, m.nIKH, self._emap[j]
        w = 0.0
        if b.tolerance:     # the prior's balanced bound over both sets (RoundingBound.prior_beta)
            enm = max(en, env)
            prior = (e.nPhi * enm + b._rho_step(e, dt, xs, xs1, enm, None, None)) * (1.0 + 4.0 * _U)
            w = b.stamp_error(m.H, f.x_minus, prior)
        b.w = w
        rho = (nIKH * (b._rho_step(e, dt, xs, xs1, en, None, None) + gap * en) + rc + emap * en) * (1.0 + 4.0 * _U)
        beta = (self._c[j] * self.beta + self._h[j] * rho + self._g[j] * w) * (1.0 + 8.0 * _U)
        betav = math.inf
        if self.noisy:
            rhov = (nIKH * (b._rho_step(e, dt, xs, xs1, env, None, None) + gap * env) + rc + emap * env) \
                * (1.0 + 4.0 * _U)
            vn = math.sqrt(b._wc(f.y.size, b.noise_max[channel - 1])) * (1.0 + 2.0 * _U)
            betav = (self._cv[j] * self.betav + self._hv[j] * rhov + self._gv[j] * vn) * (1.0 + 8.0 * _U)
        if not (math.isfinite(beta) and (not self.noisy or math.isfinite(betav))):
            b.withdrawn = b.withdrawn or ("the phase bound is no longer finite; the bounds are withdrawn until "
                                          "the next reset")
            self.j = -1
            return True
        self.beta, self.betav, self.j = beta, betav, j
        return True

    def _gap(self, ea: Any, ed: Any) -> float:
        """``>= ||D^-1 (Phi~_a - Phi~_d) D||_2`` of two ZOH entries' transitions (kept per entry):
        ``nu`` of the computed difference, whose rounding is relative ``u`` per entry."""
        got = self._gaps.get(id(ea))
        if got is None or got[0] is not ea:
            if len(self._gaps) > 256:
                self._gaps.clear()
            d = ea.scale
            G = (ea.Phi - ed.Phi) / d[:, None] * d[None, :]         # powers of two: exact
            got = self._gaps[id(ea)] = (ea, nu(G) / (1.0 - _U) * (1.0 + 2.0 * _U))
        return got[1]

    def enter(self, b: Any, f: Any) -> None:
        """After the ellipsoids' step through ``f``: the scalars from them when ``f`` is a sample of a
        periodic phase (``a P_j >= S`` proved, ``beta = sqrt(a)``; the norm of any phase may hold any
        set: the phase's constants serve the steps after it)."""
        j = f.phase
        if j < 0 or self.j >= 0 or b.withdrawn:
            return
        beta = self.norms.start(b._ell.S, j)
        betav = self.normsv.start(b._ellv.S, j) if self.noisy else 0.0
        if math.isfinite(beta) and math.isfinite(betav):
            self.beta, self.betav, self.j = beta, (betav if self.noisy else math.inf), j
            self.entered += 1

    def leave(self, b: Any) -> None:
        """The ellipsoids back from the scalars (module docstring); the scalars no longer hold."""
        j = self.j
        if j < 0:
            return
        self.j = -1
        self.left += 1
        b._ell.S, b._ell.tr = self._ellipsoid(self.norms, self.beta, j, b.d)
        if self.noisy:
            b._ellv.S, b._ellv.tr = self._ellipsoid(self.normsv, self.betav, j, b.d)

    def _ellipsoid(self, pn: PhaseNorms, beta: float, j: int, d: np.ndarray) -> tuple[np.ndarray, float]:
        """``(S, >= trace S)`` with ``S >= beta^2 P_j`` proved (``P_j`` of ``pn``), else the ball of
        radius ``sqrt(t_j) beta``."""
        P = pn.shapes[j]
        b2 = beta * beta
        a = (1.0 / b2) * (1.0 - 4.0 * _U) if b2 > 0.0 else math.inf    # <= 1 / beta^2
        if math.isfinite(a) and math.isfinite(b2):
            for margin in _BACK:
                S = P * (b2 * (1.0 + margin))
                if dominates(a, S, P):
                    return S, float(np.trace(S)) * (1.0 + 2.0 * gamma(self.n + 2))
        ball = ErrorEllipsoid(self.n, pn.bound(beta, j) * (1.0 + 4.0 * _U), d)
        return ball.S, ball.tr * (1.0 + 2.0 * gamma(self.n + 2))

    # ------------------------------------------------------------------ reads
    def later(self, b: Any, e: Any, dt: float, x: np.ndarray, xp: np.ndarray, v: np.ndarray | None,
              u: np.ndarray | None, extra: float = 0.0) -> tuple[float, float | None]:
        """``(exact, noise)`` norm bounds of the sets ``dt`` after the last sample, stepped by the ZOH
        entry ``e`` (``x`` the estimate at the sample, ``xp`` at ``t``, ``v`` and ``u`` what is held,
        ``extra`` an input change's residual), the scalars kept: ``e^- = Phi~ e + r`` with ``||D^-1 r||
        <= rho`` (the ellipsoid's residual, :meth:`~switchobs_core.bounds.rigorous.RoundingBound.rho_step`),
        so ``||e^-|| <= nu(Phi~) sqrt(t_j) beta + max(D) rho`` (``nu`` of the entry's map in the user's
        units, :func:`~switchobs_core.numerics.expm_bound.nu`). Looser than the ellipsoid's step (no shape
        kept) but O(n^2), for the reads at a later time and the innovation test's prior."""
        j = self.j
        nE = self._nu_map(e)
        dmax = self._dmax(b)
        xs, xs1 = b.xn(x), b.xn(xp)
        out = []
        for pn, beta, on in ((self.norms, self.beta, True), (self.normsv, self.betav, self.noisy)):
            if not on:
                out.append(None)
                continue
            en = pn.balanced(beta, j)
            rho = b._rho_step(e, dt, xs, xs1, en, v, u) + extra
            out.append((nE * pn.bound(beta, j) + dmax * rho) * (1.0 + 8.0 * _U))
        return out[0], out[1]

    def _nu_map(self, e: Any) -> float:
        """``>= ||Phi~||_2`` of a ZOH entry's error map in the user's units (kept per entry)."""
        got = self._nus.get(id(e))
        if got is None or got[0] is not e:
            if len(self._nus) > 64:
                self._nus.clear()
            got = self._nus[id(e)] = (e, nu(e.E))
        return got[1]

    @staticmethod
    def _dmax(b: Any) -> float:
        """``max(D)`` (powers of two: ``||D x|| <= max(D) ||x||`` exactly)."""
        return float(np.max(b.d))

    def bounds(self) -> tuple[float, float | None]:
        """``(exact, noise)`` while the scalars hold: ``sqrt(t_j) beta`` of each (noise None without a
        noise set)."""
        j, up = self.j, 1.0 + 4.0 * _U        # PhaseNorms.bound: sqrt(t_j) beta, rounded up
        return self._st[j] * self.beta * up, (self._stv[j] * self.betav * up if self.noisy else None)
