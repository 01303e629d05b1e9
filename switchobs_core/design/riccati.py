"""The exact discretisation of the plant and the periodic Riccati recursion (beyond the paper).

The filter's step formulas (prediction, gain, Joseph correction) are those of
:mod:`switchobs_core.numerics.kalman_step`; the offline periodic design (:mod:`switchobs_core.design.kalman`)
and the online filter (:mod:`switchobs_core.runtime.kalman_online`) use them with the steps built here.

Between two samples ``dt`` apart the plant ``xdot = A x + B u + w`` (e:system) with white
``w`` of intensity ``Q_c`` is discretised exactly,

.. math::

    x_{k+1} = \\Phi x_k + \\Gamma B u_k + w_k, \\quad \\Phi = e^{A dt}, \\quad
    \\Gamma = \\int_0^{dt} e^{A s} ds, \\quad
    Q_d = \\int_0^{dt} e^{A s} Q_c e^{A' s} ds

(``propagation.zoh_pair`` and ``propagation.van_loan``); one filter step then predicts with
``Phi``, ``Gamma B`` and ``Q_d`` and corrects with the rows of the active channel
(:mod:`switchobs_core.numerics.kalman_step`).

:func:`periodic_riccati` iterates the covariance recursion over whole periods of a
K-periodic sequence of steps until the priors repeat (the slow path and the cross-check of the
doubling solver of :mod:`switchobs_core.design.doubling`, which the designs use); :func:`lifted_dare` solves the same
problem through the cyclic lifting to one time-invariant DARE, a cross-check for small cases.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

from ..exceptions import RiccatiError
from ..numerics.kalman_step import predict_cov, riccati_step, symmetrize
from ..numerics.propagation import (
    COMPOSE_GRID,
    DEFAULT_DT_RESOLUTION,
    quantize_dt,
    split_step,
    taylor_pair,
    van_loan,
    zoh_pair,
)

__all__ = [
    "Step",
    "discretize",
    "DiscretizationCache",
    "PeriodicSolution",
    "rel_change",
    "covariance_run",
    "meet_periodic",
    "periodic_riccati",
    "lifted_dare",
]


@dataclass(frozen=True, eq=False)
class Step:
    """One sample of a (periodic) sequence: the prediction into it and the correction at it.

    Attributes
    ----------
    Phi, Q_d : (n, n) ndarray
        Transition and process noise covariance from the previous sample (``dt`` seconds).
    H : (p, n) ndarray
        Rows of the active channel used at this sample.
    R : (p, p) ndarray
        Their measurement noise covariance.
    """

    Phi: np.ndarray
    Q_d: np.ndarray
    H: np.ndarray
    R: np.ndarray


def discretize(A: np.ndarray, B: np.ndarray, Q_c: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation over ``dt``: ``(Phi, Gamma B, Q_d)`` (module docstring)."""
    Phi, Qd = van_loan(A, Q_c, dt)
    if not B.size:                    # no input: van Loan's exponential alone gives Phi
        return Phi, np.zeros((A.shape[0], 0)), Qd
    Phi, Gamma = zoh_pair(A, dt)
    return Phi, Gamma @ B, Qd


class DiscretizationCache:
    """LRU cache of :func:`discretize` per step ``dt`` rounded to ``dt_resolution`` (default 1 ns).

    ``cache.get(dt) -> (Phi, Gamma B, Q_d)`` of the rounded step, which is the step propagated
    (as :class:`~switchobs_core.numerics.propagation.ZOHCache` does for the Luenberger gains).
    """

    def __init__(self, A: np.ndarray, B: np.ndarray, Q_c: np.ndarray, *, maxsize: int = 64,
                 dt_resolution: float | None = DEFAULT_DT_RESOLUTION) -> None:
        self.A, self.B, self.Q_c = A, B, Q_c
        self.maxsize = max(1, int(maxsize))
        self.dt_resolution = dt_resolution
        self._lru: OrderedDict = OrderedDict()
        self._q23: tuple[np.ndarray, np.ndarray] | None = None
        self.hits = 0
        self.misses = 0

    def _short_step_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """The constant matrices of the short step's third-order ``Q_d(r)``: ``A Q + (A Q)'`` (of
        ``r^2/2``) and ``A A Q + 2 A Q A' + (A A Q)'`` (of ``r^3/6``), computed once (``A`` and ``Q_c``
        do not change after construction); the same doubles as computing them for every step."""
        if self._q23 is None:
            A, Qc = self.A, self.Q_c
            AQ = A @ Qc
            self._q23 = (AQ + AQ.T, A @ AQ + 2 * AQ @ A.T + (A @ AQ).T)
        return self._q23

    def get(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Phi, Gamma B, Q_d)`` of the step ``dt`` (rounded)."""
        dtq = quantize_dt(dt, self.dt_resolution)
        key = round(dtq / self.dt_resolution) if self.dt_resolution else dtq
        e = self._lru.get(key)
        if e is not None:
            self.hits += 1
            self._lru.move_to_end(key)
            return e
        self.misses += 1
        qc, r = split_step(dtq, self.dt_resolution)
        if qc > 0 and r > 0:
            # a jittered step: the cached grid step composed with a short one (as ZOHCache does);
            # Q_d(a + r) = e^{A r} Q_d(a) e^{A r}' + Q_d(r), Q_d(r) to third order in r (a covariance,
            # not a bound: the O(r^4) remainder is ~1e-16 relative at r < 1e-4 s)
            bk = ("grid", qc)
            base = self._lru.get(bk)
            if base is None:
                base = self._lru[bk] = discretize(self.A, self.B, self.Q_c, qc * COMPOSE_GRID)
            Phi_a, GB_a, Qd_a = base
            Ps, Gs = taylor_pair(self.A, r)
            q2, q3 = self._short_step_terms()
            Qd_r = self.Q_c * r + q2 * (r * r / 2) + q3 * (r ** 3 / 6)
            Qd = Ps @ Qd_a @ Ps.T + Qd_r
            e = (Ps @ Phi_a, Ps @ GB_a + Gs @ self.B, 0.5 * (Qd + Qd.T))
        else:
            e = discretize(self.A, self.B, self.Q_c, dtq)
        self._lru[key] = e
        while len(self._lru) > self.maxsize:
            self._lru.popitem(last=False)
        return e


@dataclass(frozen=True, eq=False)
class PeriodicSolution:
    """Result of :func:`periodic_riccati` and of the doubling solver
    (:func:`~switchobs_core.design.doubling.solve_periodic_riccati`).

    Attributes
    ----------
    P_prior : list of (n, n) ndarray
        The periodic prior covariance ``P^-_k`` at each phase k = 0..K-1.
    K : list of (n, p_k) ndarray
        The gains ``K_k`` at each phase (full rows of its step).
    periods : int
        Whole periods iterated (doubling: doublings plus sweeps).
    change : float
        Relative change of the prior of a phase over the last period (the residual of the
        periodic Riccati equation).
    startup_P, startup_K : list of ndarray
        Priors and gains of the run from ``P0`` at samples 0..S-1, before it meets the
        periodic solution (relative tolerance ``startup_rtol``; empty from the doubling solver).
    doublings : int
        Doublings of the period map (0 for the plain iteration).
    transition, rho : ndarray or None, float
        The period's closed-loop error map and its spectral radius (doubling solver only).
    """

    P_prior: list[np.ndarray]
    K: list[np.ndarray]
    periods: int
    change: float
    startup_P: list[np.ndarray]
    startup_K: list[np.ndarray]
    doublings: int = 0
    transition: np.ndarray | None = None
    rho: float = float("nan")


def rel_change(P: np.ndarray, Q: np.ndarray) -> float:
    """``max |P - Q| / max |Q|`` (entrywise): the relative distance of two covariances, O(n^2) (the
    measure the observer's re-lock uses; within a factor n of the 2-norm ratio)."""
    return float(np.abs(P - Q).max() / max(np.abs(Q).max(), np.finfo(float).tiny))


def covariance_run(steps: Sequence[Step], P0: np.ndarray, *, first_predict: bool = False) -> Iterator[tuple]:
    """The recursion from ``P^-_0 = P0`` (``first_predict``: ``Phi_0 P0 Phi_0' + Q_d,0``), Joseph form,
    endless: ``(P^-_k, K_k)`` for k = 0, 1, ..."""
    K = len(steps)
    P = symmetrize(np.asarray(P0, dtype=float))
    if first_predict:
        P = predict_cov(P, steps[0].Phi, steps[0].Q_d)
    k = 0
    while True:
        Kk, Pp = riccati_step(P, steps[k % K].H, steps[k % K].R)
        yield P, Kk
        k += 1
        P = predict_cov(Pp, steps[k % K].Phi, steps[k % K].Q_d)


def meet_periodic(run: Iterator[tuple], periodic: Sequence[np.ndarray], *, rtol: float,
                  max_samples: int | None = None) -> tuple[list[np.ndarray], list[np.ndarray], float]:
    """The prefix of ``run`` before it meets the periodic solution: ``(priors, gains, change)``.

    ``run`` yields ``(P^-_k, K_k)`` from sample 0. It meets the periodic solution when the priors
    of one whole period (K consecutive samples) each agree with the periodic prior of their phase
    within ``rtol`` (:func:`rel_change`); the start-up ends where that period begins. At most
    ``max_samples`` (default 64 periods) are kept; ``change`` is the largest distance over the
    last K samples run (<= rtol when it met).
    """
    K = len(periodic)
    cap = 64 * K if max_samples is None else max(0, int(max_samples))
    Ps: list[np.ndarray] = []
    Ks: list[np.ndarray] = []
    dist: list[float] = []
    good = 0
    for k, (P, Kk) in enumerate(run):
        d = rel_change(P, periodic[k % K])
        good = good + 1 if d <= rtol else 0
        dist.append(d)
        if good >= K or k + 1 >= cap + K:
            break
        if k < cap:
            Ps.append(P)
            Ks.append(Kk)
    S = len(dist) - K if good >= K else min(len(Ps), cap)
    return Ps[:S], Ks[:S], float(max(dist[-K:]))


def periodic_riccati(
    steps: Sequence[Step],
    P0: np.ndarray,
    *,
    rtol: float = 1e-12,
    startup_rtol: float = 1e-11,
    max_periods: int = 500,
    first_predict: bool = False,
    floor_rtol: float = 1e-8,
    max_startup: int | None = None,
) -> PeriodicSolution:
    """Periodic solution of the Riccati recursion of a K-periodic step sequence, and its start-up:
    the plain iteration, period by period (the cross-check of the doubling solver).

    ``sol = periodic_riccati(steps, P0)``

    The recursion runs from ``P^-_0 = P0`` (or ``Phi_0 P0 Phi_0' + Q_d,0`` with
    ``first_predict``) through whole periods ``steps[0], ..., steps[K-1]`` until the prior
    covariance of every phase changes by at most ``rtol`` (relative) from one period to
    the next (:func:`rel_change`), or the change stops falling (the rounding floor of a large system) below
    ``floor_rtol``. Only the last two periods are kept. Then the start-up is the run from ``P0``
    again, up to where it meets the periodic solution (:func:`meet_periodic`, ``startup_rtol``,
    at most ``max_startup`` samples; ``startup_rtol = 0`` skips it).

    Raises
    ------
    RiccatiError
        No convergence within ``max_periods`` periods (the message gives the last change).
    """
    K = len(steps)
    if K == 0:
        raise RiccatiError("periodic_riccati needs at least one step")
    run = covariance_run(steps, P0, first_predict=first_predict)
    prev: list[np.ndarray] = []
    change, last = np.inf, np.inf
    periods = 0
    while periods < max_periods:
        # 1. one period; only this one and the previous one are kept
        cur = [next(run) for _ in range(K)]
        periods += 1
        if prev:
            # 2. relative change of every phase's prior between the last two periods
            change = max(rel_change(cur[k][0], prev[k][0]) for k in range(K))
            if change <= rtol or (change <= floor_rtol and change >= 0.5 * last):
                break
            last = change
        prev = cur
    else:
        raise RiccatiError(
            f"periodic Riccati recursion did not converge in {max_periods} periods (last relative change "
            f"{change:.3g} > {rtol:g}); a process intensity that does not excite every marginal or unstable mode "
            "makes the covariance decay like 1/t instead of converging: increase Q_c, or raise max_periods"
        )
    per_P = [P for P, _ in cur]
    per_K = [Kk for _, Kk in cur]
    # 3. start-up: the run from P0 until it meets the periodic solution
    su_P: list[np.ndarray] = []
    su_K: list[np.ndarray] = []
    if startup_rtol > 0:
        su_P, su_K, _ = meet_periodic(covariance_run(steps, P0, first_predict=first_predict), per_P,
                                      rtol=startup_rtol, max_samples=max_startup)
    return PeriodicSolution(per_P, per_K, periods, float(change), su_P, su_K)


def lifted_dare(steps: Sequence[Step]) -> list[np.ndarray]:
    """Periodic priors ``P^-_k`` from the cyclically lifted DARE (a cross-check for small cases).

    The K-periodic system ``x_{k+1} = Phi_{k+1} x_k + w_k``, ``y_k = H_k x_k + v_k`` is
    rewritten as one time-invariant system of dimension nK with the block-cyclic transition
    ``F[k+1, k] = Phi_{k+1}``, ``H_c = blkdiag(H_k)``, ``Q = blkdiag(Q_d,k)``,
    ``R = blkdiag(R_k)``; the stabilising solution of its filter DARE is
    ``blkdiag(P^-_0, ..., P^-_{K-1})`` (Bittanti and Colaneri, cyclic reformulation).
    Costs O((nK)^3): use it for small n K only.
    """
    K = len(steps)
    n = steps[0].Phi.shape[0]
    ps = [st.H.shape[0] for st in steps]
    off = np.concatenate([[0], np.cumsum(ps)])
    F = np.zeros((n * K, n * K))
    Q = np.zeros((n * K, n * K))
    Hc = np.zeros((off[-1], n * K))
    Rc = np.zeros((off[-1], off[-1]))
    for k, st in enumerate(steps):
        j = (k + 1) % K
        F[j * n:(j + 1) * n, k * n:(k + 1) * n] = steps[j].Phi
        Q[j * n:(j + 1) * n, j * n:(j + 1) * n] = steps[j].Q_d
        Hc[off[k]:off[k + 1], k * n:(k + 1) * n] = st.H
        Rc[off[k]:off[k + 1], off[k]:off[k + 1]] = st.R
    # filter DARE: P = F P F' - F P H' (H P H' + R)^-1 H P F' + Q  (dual of the control DARE)
    X = solve_discrete_are(F.T, Hc.T, Q, Rc)
    return [symmetrize(X[k * n:(k + 1) * n, k * n:(k + 1) * n]) for k in range(K)]
