"""The periodic discrete Riccati equation by structure-preserving doubling (beyond the paper).

The prior covariance of the Kalman filter of a K-periodic step sequence (:mod:`switchobs_core.design.riccati`) obeys
``P^-_{k+1} = F_k(P^-_k)`` with the one-sample Riccati map of phase k (correct with ``H_k``,
then predict with ``Phi_{k+1}``, ``Q_{d,k+1}``, indices mod K)

.. math::

    F_k(X) = Q_{d,k+1} + \\Phi_{k+1} X (I + G_k X)^{-1} \\Phi_{k+1}', \\quad G_k = H_k' R_k^{-1} H_k

(the matrix-inversion-lemma form of ``Phi (X - X H' S^{-1} H X) Phi' + Q_d``). A map of this
form is a *triple* ``(A, G, Q)``: ``X -> Q + A X (I + G X)^{-1} A'``, and triples compose into
triples (the symplectic structure the structured doubling algorithm, SDA, preserves; Hench and
Laub, "Numerical solution of the discrete-time periodic Riccati equation", IEEE TAC 39(6),
1994; Chu, Fan, Lin and Wang, "Structure-preserving algorithms for periodic discrete-time
algebraic Riccati equations", Int. J. Control 77(8), 2004): with ``W = I + Q_1 G_2``,

.. math::

    (A_2, G_2, Q_2) \\circ (A_1, G_1, Q_1) = (A_2 W^{-1} A_1,\\;
    G_1 + A_1' G_2 W^{-1} A_1,\\; Q_2 + A_2 W^{-1} Q_1 A_2').

Algorithm of :func:`solve_periodic_riccati`:

1. *Period map.* The K one-sample maps composed from phase 0, ``F = F_{K-1} o ... o F_0``. A
   one-sample map has ``G_k`` of rank p, so each composition is the Kalman step itself
   (``K = Q H' S^{-1}``, ``W^{-1} = I - K H``): ``A <- Phi (I - K H) A``,
   ``G <- G + (H A)' S^{-1} (H A)``, ``Q <- Phi [(I - K H) Q (I - K H)' + K R K'] Phi' + Q_d``
   (Joseph form), with ``Q`` carried as a square root (QR updates) so that it stays positive
   semidefinite over the dynamic range of long blind stretches (an unstable mode unseen for
   30 s grows its variance by e^60). ``Q`` of the period map is the recursion from ``P = 0``
   over one period, ``A`` its closed-loop transition, ``G`` its information.
2. *Doubling.* ``F <- F o F`` squares the number of periods: after j steps ``Q_j = F^{2^j}(0)``,
   which converges quadratically to the periodic prior ``P^-_0`` (``A_j -> 0`` like
   ``rho^{2^j}``, rho the closed-loop spectral radius per period); stop when ``Q_j`` changes by
   at most ``rtol`` (relative, :func:`~switchobs_core.design.riccati.rel_change`).
3. *Sweep.* From ``P^-_0`` one period of square-root Kalman steps gives every phase's prior and
   gain, and the prior of the next period's phase 0; its distance from ``P^-_0`` is the residual
   of the periodic Riccati equation, reported as ``change``. The doubling lands on the fixed
   point of the *computed* period map, so one sweep is normally all (residual ~1e-15 for the
   paper's model, ~1e-9 for 32 agents, whose covariances span e^60: the rounding floor); a sweep
   repeats from where the last one ended (at most ``max_sweeps`` times, each contracting the
   error by rho^2) while the residual exceeds ``max(rtol, floor_rtol)``.
4. *Stabilising.* The closed-loop error map of the period, ``prod (I - K_k H_k) Phi_k``, must
   have spectral radius < 1 (else the solution is not the stabilising one: a marginal mode the
   process noise never excites).

Memory: the K priors (O(K n^2), the result; one period's at a time, a sweep drops the last
sweep's before it starts) and O(n^2) work space; nothing per iteration. Time:
about three periods of Kalman steps, against ``log(rtol) / log(rho^2)`` periods for the plain
iteration :func:`~switchobs_core.design.riccati.periodic_riccati` (kept as the cross-check).

Start-up (:func:`startup_run`): the recursion from ``P0`` until every prior of one whole period
agrees with the periodic one of its phase within a tolerance, stored sample by sample.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from ..exceptions import RiccatiError
from ..numerics.kalman_step import psd_sqrt, sqrt_correct, sqrt_predict, symmetrize
from .riccati import PeriodicSolution, Step, meet_periodic, rel_change

__all__ = [
    "RiccatiMap",
    "period_map",
    "fixed_point",
    "solve_periodic_riccati",
    "sqrt_run",
    "startup_run",
    "closed_loop_transition",
]

#: Largest number of doublings (2^60 periods): a map that has not settled by then never will.
MAX_DOUBLINGS = 60


@dataclass(frozen=True, eq=False)
class RiccatiMap:
    """The map ``X -> Q + A X (I + G X)^{-1} A'`` (module docstring), ``G``, ``Q`` symmetric PSD."""

    A: np.ndarray
    G: np.ndarray
    Q: np.ndarray

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """``Q + A X (I + G X)^{-1} A'``, symmetrised."""
        n = X.shape[0]
        # X (I + G X)^{-1} = ((I + X G)^{-1} X)  (solve, no inverse)
        Y = np.linalg.solve(np.eye(n) + X @ self.G, X)
        return symmetrize(self.Q + self.A @ Y @ self.A.T)

    def then(self, second: RiccatiMap) -> RiccatiMap:
        """``second o self`` (module docstring's composition formula)."""
        n = self.A.shape[0]
        # W = I + Q_1 G_2
        lu = lu_factor(np.eye(n) + self.Q @ second.G, check_finite=False)
        WA = lu_solve(lu, self.A, check_finite=False)
        WQ = lu_solve(lu, self.Q, check_finite=False)
        # A = A_2 W^-1 A_1, G = G_1 + A_1' G_2 W^-1 A_1, Q = Q_2 + A_2 W^-1 Q_1 A_2'
        return RiccatiMap(second.A @ WA, symmetrize(self.G + self.A.T @ second.G @ WA),
                          symmetrize(second.Q + second.A @ WQ @ second.A.T))

    def doubled(self) -> RiccatiMap:
        """``self o self``: the map over twice as many periods."""
        return self.then(self)


class _Factors:
    """Square roots of ``R_k`` and ``Q_{d,k}`` of a step sequence, computed once per distinct matrix."""

    def __init__(self, steps: Sequence[Step]) -> None:
        self._memo: dict[int, np.ndarray] = {}
        self.R = [self._get(st.R) for st in steps]
        self.Q = [self._get(st.Q_d) for st in steps]

    def _get(self, M: np.ndarray) -> np.ndarray:
        f = self._memo.get(id(M))
        if f is None:
            f = self._memo[id(M)] = psd_sqrt(M) if M.size else M
        return f


def period_map(steps: Sequence[Step], factors: _Factors | None = None) -> RiccatiMap:
    """The Riccati map of one whole period from the prior of phase 0 (module docstring, step 1)."""
    K = len(steps)
    n = steps[0].Phi.shape[0]
    fac = _Factors(steps) if factors is None else factors
    A, G, L = np.eye(n), np.zeros((n, n)), np.zeros((n, n))
    for k, st in enumerate(steps):
        j = (k + 1) % K
        Kk, L, Ss = sqrt_correct(L, st.H, fac.R[k])
        if st.H.shape[0]:
            HA = st.H @ A
            # G <- G + (H A)' S^-1 (H A) = Z' Z with Z = S^{-1/2} H A;  A <- (I - K H) A
            Z = np.linalg.solve(Ss, HA)
            G = symmetrize(G + Z.T @ Z)
            A = A - Kk @ HA
        # predict into phase k + 1: A <- Phi A, Q <- Phi Q Phi' + Q_d
        A = steps[j].Phi @ A
        L = sqrt_predict(L, steps[j].Phi, fac.Q[j])
    return RiccatiMap(A, G, symmetrize(L @ L.T))


def _sweep(steps: Sequence[Step], P: np.ndarray) -> tuple[np.ndarray, list, list]:
    """One period of square-root Kalman steps from the prior ``P`` of phase 0 (:func:`sqrt_run`):
    the prior of the next period's phase 0, and every phase's prior and gain."""
    run = sqrt_run(steps, P)
    out = [next(run) for _ in range(len(steps))]
    return next(run)[0], [P for P, _ in out], [Kk for _, Kk in out]


def closed_loop_transition(steps: Sequence[Step], K: Sequence[np.ndarray]) -> np.ndarray:
    """``prod_k (I - K_k H_k) Phi_k`` over one period, from the posterior of phase 0 to that of the
    next period's phase 0 (phases 1..K-1, then 0): the noise-free error map (e:error_dynamics sampled)."""
    n = steps[0].Phi.shape[0]
    M = np.eye(n)
    for k in [*range(1, len(steps)), 0]:
        E = steps[k].Phi @ M
        M = E - K[k] @ (steps[k].H @ E)
    return M


def fixed_point(F: RiccatiMap, *, rtol: float = 1e-12) -> tuple[np.ndarray, int, float]:
    """The fixed point ``X = F(X)`` reached from 0 by doubling: ``(X, doublings, change)``.

    ``F <- F o F`` until ``Q`` (``= F^{2^j}(0)``) changes by at most ``rtol``
    (:func:`~switchobs_core.design.riccati.rel_change`; module docstring, step 2).

    Raises
    ------
    RiccatiError
        Overflow, or no settling in :data:`MAX_DOUBLINGS` doublings.
    """
    doublings = 0
    while True:
        F2 = F.doubled()
        doublings += 1
        change = rel_change(F2.Q, F.Q)
        F = F2
        if not np.all(np.isfinite(F.Q)):
            raise RiccatiError(f"periodic Riccati doubling overflowed after {doublings} doublings: the "
                               "sampled schedule is not detectable or the covariance exceeds floating point")
        if change <= rtol:
            return F.Q, doublings, change
        if doublings >= MAX_DOUBLINGS:
            raise RiccatiError(
                f"periodic Riccati doubling did not settle in {MAX_DOUBLINGS} doublings (2^{MAX_DOUBLINGS} periods; "
                f"last relative change {change:.3g} > {rtol:g}); a process intensity that does not excite every "
                "marginal or unstable mode has no stabilising solution: increase Q_c")


def solve_periodic_riccati(
    steps: Sequence[Step],
    *,
    rtol: float = 1e-12,
    floor_rtol: float = 1e-8,
    max_sweeps: int = 8,
) -> PeriodicSolution:
    """Periodic prior covariances and gains of a K-periodic step sequence by doubling (module docstring).

    ``sol = solve_periodic_riccati(steps)``; ``sol.P_prior[k]``, ``sol.K[k]``; no start-up
    (:func:`startup_run` adds one).

    Parameters
    ----------
    steps : sequence of Step
        One period; ``steps[k].Phi``, ``Q_d`` predict into sample k, ``H``, ``R`` correct at it.
    rtol : float
        Relative change (:func:`~switchobs_core.design.riccati.rel_change`) at which the doubling and the sweeps stop.
    floor_rtol : float
        Residual accepted after a sweep (the rounding floor of large systems; default 1e-8).
    max_sweeps : int
        Most sweeps after the doubling.

    Raises
    ------
    RiccatiError
        The doubling or the sweeps do not settle, or the solution is not stabilising.
    """
    K = len(steps)
    if K == 0:
        raise RiccatiError("solve_periodic_riccati needs at least one step")
    fac = _Factors(steps)
    # 1. the period map from phase 0
    F = period_map(steps, fac)
    # 2. doubling: Q_j = F^{2^j}(0) -> P^-_0
    P0, doublings, change = fixed_point(F, rtol=rtol)
    # 3. sweeps from P^-_0 until phase 0 comes back (or the change settles at the rounding floor)
    sweeps = 0
    for sweeps in range(1, int(max_sweeps) + 1):  # noqa: B007 (counted after the loop)
        Ps = Ks = []                          # the last sweep's priors go before the next are made
        nxt, Ps, Ks = _sweep(steps, P0)
        change = rel_change(nxt, P0)
        if change <= max(rtol, floor_rtol):
            break
        P0 = nxt
    else:
        if change > floor_rtol:
            raise RiccatiError(
                f"periodic Riccati sweeps after the doubling did not settle in {max_sweeps} periods (relative "
                f"change {change:.3g} > {floor_rtol:g})")
    # 4. the stabilising solution: closed-loop spectral radius < 1
    M = closed_loop_transition(steps, Ks)
    rho = float(np.max(np.abs(np.linalg.eigvals(M))))
    if not rho < 1.0:
        raise RiccatiError(
            f"the periodic Riccati solution is not stabilising (closed-loop spectral radius per period {rho:.6g} "
            ">= 1): a marginal or unstable mode is not excited by the process noise or never observed; "
            "increase Q_c or check detectability")
    return PeriodicSolution(Ps, Ks, doublings + sweeps, float(change), [], [], doublings=doublings,
                            transition=M, rho=rho)


def sqrt_run(steps: Sequence[Step], P0: np.ndarray, *, first_predict: bool = False) -> Iterator[tuple]:
    """The recursion from ``P^-_0 = P0`` (``first_predict``: ``Phi_0 P0 Phi_0' + Q_d,0``) in square-root
    form, endless: ``(P^-_k, K_k)`` for k = 0, 1, ..."""
    K = len(steps)
    fac = _Factors(steps)
    P = symmetrize(np.asarray(P0, dtype=float))
    if first_predict:
        P = symmetrize(steps[0].Phi @ P @ steps[0].Phi.T + steps[0].Q_d)
    L = psd_sqrt(P)
    k = 0
    while True:
        Kk, Lp, _ = sqrt_correct(L, steps[k % K].H, fac.R[k % K])
        yield P, Kk
        k += 1
        st = steps[k % K]
        # P^- = Phi P^+ Phi' + Q_d, with its square root [Phi L^+, Q_d^{1/2}]
        PhiL = st.Phi @ Lp
        P = symmetrize(PhiL @ PhiL.T + st.Q_d)
        L = np.hstack([PhiL, fac.Q[k % K]])


def startup_run(steps: Sequence[Step], periodic: Sequence[np.ndarray], P0: np.ndarray, *,
                rtol: float = 1e-11, max_samples: int | None = None,
                first_predict: bool = False) -> tuple[list[np.ndarray], list[np.ndarray], float]:
    """The start-up from ``P0`` (square-root steps, :func:`sqrt_run`) up to where it meets the periodic
    solution (:func:`~switchobs_core.design.riccati.meet_periodic`): ``(priors, gains, change)``."""
    return meet_periodic(sqrt_run(steps, P0, first_predict=first_predict), periodic, rtol=rtol,
                         max_samples=max_samples)
