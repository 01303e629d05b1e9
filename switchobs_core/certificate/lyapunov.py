"""A common quadratic Lyapunov function for a finite set of cycle maps (a semidefinite program).

For cycle maps ``Phi_j``: ``P >= I`` with ``Phi_j' P Phi_j <= rho^2 P`` for all j, so
``||x_tilde(t_k)|| <= sqrt(cond P) rho^k ||x_tilde(0)||`` for *any* order of those cycles;
verified in floating point after the solve (cvxpy is imported only when solving).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument
from ..validation import as_finite, as_matrix

__all__ = ["LyapunovCertificate", "common_lyapunov"]


@dataclass(frozen=True)
class LyapunovCertificate:
    """A common quadratic Lyapunov function for a finite set of cycle maps.

    Attributes
    ----------
    rho : float
        Verified rate: ``Phi_j' P Phi_j <= rho^2 P`` holds in floating point for all j
        (checked on the eigenvalues of ``rho^2 P - Phi_j' P Phi_j``).
    rho_lower : float
        ``max_j rho(Phi_j)`` (spectral radii): a proven lower bound on the rate of any
        certificate, since the joint spectral radius is at least it.
    P : (n, n) ndarray
        ``P >= I``.
    cond : float
        ``cond(P)``: ``||x_k|| <= sqrt(cond) rho^k ||x_0||`` for any order of the cycles.
    min_eig : float
        Smallest eigenvalue of ``rho^2 P - Phi_j' P Phi_j`` over j (>= 0 when verified).
    verified : bool
    ok : bool
        ``verified and rho < 1``.
    """

    rho: float
    rho_lower: float
    P: np.ndarray
    cond: float
    min_eig: float
    verified: bool
    solves: int = 0

    @property
    def ok(self) -> bool:
        return self.verified and self.rho < 1.0


def _rate_of(P: np.ndarray, Phis: Sequence[np.ndarray]) -> float:
    """Smallest rho with ``Phi' P Phi <= rho^2 P``: ``max ||R Phi R^-1||``, ``P = R' R``."""
    R = np.linalg.cholesky(P).T
    Rinv = np.linalg.inv(R)
    return max(float(np.linalg.norm(R @ Phi @ Rinv, 2)) for Phi in Phis)


def _solve_feasibility(prob) -> bool:
    """Solve an LMI feasibility problem (Clarabel, no warm start, solver warnings silenced).

    True if the solver reports a (possibly inaccurate) solution; False on infeasibility or a
    solver failure. Callers verify any solution in floating point themselves.
    """
    import cvxpy as cp

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(solver=cp.CLARABEL, warm_start=False)
    except cp.error.SolverError:
        return False
    return prob.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def _verify(P: np.ndarray, Phis: Sequence[np.ndarray], rho: float) -> float:
    """Smallest eigenvalue of ``rho^2 P - Phi_j' P Phi_j`` over j, minus a rounding allowance.

    Forming the matrix and its eigenvalues in floating point errs by a few ``n eps`` times
    ``||P|| (rho^2 + ||Phi_j||^2)``; that amount is subtracted, so a result >= 0 proves the
    inequality for the exact matrices.
    """
    n = P.shape[0]
    eps = np.finfo(float).eps
    normP = np.linalg.norm(P, 2)
    worst = np.inf
    for Phi in Phis:
        M = rho ** 2 * P - Phi.T @ P @ Phi
        allow = 16 * n * eps * normP * (rho ** 2 + np.linalg.norm(Phi, 2) ** 2)
        worst = min(worst, float(np.linalg.eigvalsh(0.5 * (M + M.T))[0]) - allow)
    return worst


def common_lyapunov(Phis: Sequence[Any], *, rel_tol: float = 1e-3, margin: float = 1e-6,
                    theta_max: float = 1e8, max_iter: int = 40) -> LyapunovCertificate:
    """Common quadratic Lyapunov function for cycle maps ``Phi_j`` (bisection on rho).

    ``cert = common_lyapunov([Phi_1, Phi_2, ...])``

    For fixed ``rho`` the LMI feasibility problem

    .. math::

        P = P^T, \\quad I \\preceq P \\preceq \\theta_{max} I, \\quad
        \\Phi_j^T P \\Phi_j \\preceq \\rho^2 P \\quad \\forall j

    is solved with Clarabel (``warm_start=False``); ``rho`` is bisected between
    ``max_j rho(Phi_j)`` and ``max_j ||Phi_j||`` (feasible with ``P = I``). Every feasible
    ``P`` is then re-checked in floating point: its exact rate
    ``max_j ||R Phi_j R^{-1}||`` (``P = R'R``) is computed, inflated by ``margin``
    (relative), and the eigenvalues of ``rho^2 P - Phi_j' P Phi_j`` are required to be
    >= 0. The reported ``rho`` is that verified value.

    Parameters
    ----------
    Phis : sequence of (n, n) array_like
    rel_tol : float
        Relative width at which bisection stops.
    margin : float
        Relative inflation of the verified rate.
    theta_max : float
        Upper bound on ``P`` (keeps the SDP bounded).
    max_iter : int

    Returns
    -------
    LyapunovCertificate
    """
    import cvxpy as cp

    Phis = [as_matrix(F, f"Phis[{j}]", square=True) for j, F in enumerate(Phis)]
    if not Phis:
        raise InvalidArgument("Phis must hold at least one matrix")
    n = Phis[0].shape[0]
    if any(F.shape != (n, n) for F in Phis):
        raise InvalidArgument("Phis must all be square of one size")
    for name, v in (("rel_tol", rel_tol), ("margin", margin), ("theta_max", theta_max)):
        v = as_finite(v, name)
        if v <= 0 if name != "margin" else v < 0:
            raise InvalidArgument(f"{name} must be > 0; got {v}")
    if int(max_iter) < 1:
        raise InvalidArgument(f"max_iter must be >= 1; got {max_iter}")
    lo = max(float(np.max(np.abs(np.linalg.eigvals(F)))) for F in Phis)
    best_P = np.eye(n)
    hi = _rate_of(best_P, Phis) * (1 + margin)
    P = cp.Variable((n, n), symmetric=True)
    rho2 = cp.Parameter(nonneg=True)
    I = np.eye(n)
    cons = [P >> I, P << theta_max * I]
    for F in Phis:
        S = rho2 * P - F.T @ P @ F
        cons.append(0.5 * (S + S.T) >> 0)
    prob = cp.Problem(cp.Minimize(0), cons)
    solves = 0
    for _ in range(max_iter):
        if hi - lo <= rel_tol * hi:
            break
        mid = 0.5 * (lo + hi)
        rho2.value = mid ** 2
        solves += 1
        if _solve_feasibility(prob) and P.value is not None:
            Pv = 0.5 * (P.value + P.value.T)
            try:
                r = _rate_of(Pv, Phis) * (1 + margin)
            except np.linalg.LinAlgError:
                lo = mid
                continue
            if r < hi:
                hi, best_P = r, Pv
            if r > mid * (1 + 10 * rel_tol):
                # solver's answer is feasible only loosely; treat as infeasible at mid
                lo = mid
        else:
            lo = mid
    min_eig = _verify(best_P, Phis, hi)
    ev = np.linalg.eigvalsh(best_P)
    rho_lower = max(float(np.max(np.abs(np.linalg.eigvals(Phi)))) for Phi in Phis)
    return LyapunovCertificate(rho=float(hi), rho_lower=min(rho_lower, float(hi)), P=best_P,
                               cond=float(ev[-1] / ev[0]), min_eig=min_eig,
                               verified=bool(min_eig >= 0.0), solves=solves)
