"""A common quadratic Lyapunov function for a finite set of cycle maps (a semidefinite program).

For cycle maps ``Phi_j``: ``P >= I`` with ``Phi_j' P Phi_j <= rho^2 P`` for all j, so
``||x_tilde(t_k)|| <= sqrt(cond P) rho^k ||x_tilde(0)||`` for *any* order of those cycles.
The solver's ``P`` is proved in floating point (a Cholesky factorisation with an explicit
rounding allowance, :func:`lmi_proved`) at a rate backed off by :data:`BACKOFF` from the
SDP's edge, so the proof holds on any CPU (cvxpy is imported only when solving).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument
from ..numerics.rounding import UNIT_ROUNDOFF, gamma
from ..validation import as_finite, as_matrix

__all__ = ["BACKOFF", "LyapunovCertificate", "common_lyapunov", "lmi_proved"]

#: Relative back-off of a certified rate from the SDP's edge: the solver's ``P`` at rate ``r``
#: must be proved at ``r (1 + BACKOFF)``. ``1e-4`` is 10^4 times the solver's tolerance and the
#: rounding allowance of a well-conditioned ``P``, and covers perturbations of the maps of
#: relative size ``BACKOFF / sqrt(cond P)``.
BACKOFF = 1e-4
#: Smallest positive subnormal double: the underflow term of :func:`_pd_proved`.
_ETA = 2.0**-1074


@dataclass(frozen=True)
class LyapunovCertificate:
    """A common quadratic Lyapunov function for a finite set of cycle maps.

    Attributes
    ----------
    rho : float
        Verified rate: ``Phi_j' P Phi_j <= rho^2 P`` for all j, proved for the given
        floating-point ``Phi_j`` and ``P`` with rounding accounted for (:func:`lmi_proved`);
        ``(1 + BACKOFF)`` times the smallest rate at which the SDP's ``P`` was proved.
    rho_lower : float
        ``max_j rho(Phi_j)`` (spectral radii): a proven lower bound on the rate of any
        certificate, since the joint spectral radius is at least it.
    P : (n, n) ndarray
        ``P >= I``.
    cond : float
        ``cond(P)``: ``||x_k|| <= sqrt(cond) rho^k ||x_0||`` for any order of the cycles.
    min_eig : float
        Smallest eigenvalue of ``rho^2 P - Phi_j' P Phi_j`` over j (and of ``P``) less the
        proof's rounding allowance (informational; > 0 when verified).
    verified : bool
        The proof of :func:`lmi_proved` holds for ``P > 0`` and every j.
    solves : int
        SDP solves of the bisection.
    margin : float
        Relative headroom ``1 - max_j ||R Phi_j R^{-1}|| / rho`` (``P = R'R``), about
        ``BACKOFF``: every map may move by about ``margin rho / sqrt(cond P)`` (2-norm)
        before the certificate fails.
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
    margin: float = 0.0

    @property
    def ok(self) -> bool:
        return self.verified and self.rho < 1.0


def _rate_of(P: np.ndarray, Phis: Sequence[np.ndarray]) -> float:
    """Smallest rho with ``Phi' P Phi <= rho^2 P``: ``max ||R Phi R^-1||``, ``P = R' R``."""
    R = np.linalg.cholesky(P).T
    Rinv = np.linalg.inv(R)
    return max(float(np.linalg.norm(R @ Phi @ Rinv, 2)) for Phi in Phis)


def _solve_feasibility(prob) -> bool:
    """Solve an LMI problem (Clarabel, no warm start, solver warnings silenced).

    True if the solver reports a (possibly inaccurate) solution; False on infeasibility or a
    solver failure. Callers prove any solution in floating point (:func:`lmi_proved`) at a
    rate backed off by :data:`BACKOFF` before they use it.
    """
    import cvxpy as cp

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(solver=cp.CLARABEL, warm_start=False)
    except cp.error.SolverError:
        return False
    return prob.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def _pd_proved(H: np.ndarray, err: float) -> tuple[bool, float]:
    """Prove ``H_exact > 0`` for a symmetric ``H_exact`` with ``||fl(H) - H_exact||_2 <= err``.

    ``H`` is the computed matrix (its lower triangle is read). Floating-point Cholesky of
    ``H~ = fl(H - s I)`` with ``s = 2 (err + 2 gamma_{n+1} sum_i |h_ii|)`` (plus an underflow
    term). If it runs to completion, the computed factor obeys ``R'R = H~ + dH`` with
    ``|dH| <= gamma_{n+1} |R'||R|`` (Higham, ASNA Thm 10.3), so ``||dH|| <= gamma_{n+1}
    ||R||_F^2 <= gamma_{n+1} tr(H~) / (1 - gamma_{n+1})`` and ``H~ >= -||dH|| I``; the shift's
    rounding on the diagonal is at most ``u (|h_ii| + s)``. Adding up,
    ``H_exact >= (s/2)(1 - 2u) I > 0``.

    Returns
    -------
    (bool, float)
        Proved, and the informational slack ``lambda_min(H) - s`` (eigenvalues, not part of
        the proof).
    """
    n = H.shape[0]
    if not (np.all(np.isfinite(H)) and math.isfinite(err)):
        return False, -math.inf
    Hs = np.tril(H) + np.tril(H, -1).T
    d = np.abs(np.diag(Hs))
    s = 2.0 * (err + 2.0 * gamma(n + 1) * float(d.sum())) + 16.0 * n * (n + 2) * _ETA
    slack = float(np.linalg.eigvalsh(Hs)[0]) - s
    try:
        np.linalg.cholesky(Hs - s * np.eye(n))
    except np.linalg.LinAlgError:
        return False, slack
    return True, slack


def lmi_proved(c: float, P: np.ndarray, E: np.ndarray, Q: np.ndarray | None = None) -> tuple[bool, float]:
    """Prove ``c P - E' Q E >= 0`` (``Q = P`` by default) for the exact values of these floats.

    ``P`` and ``Q`` must be exactly symmetric. The computed ``H = fl(c P) - fl(fl(E' Q) E)``
    differs from the exact matrix elementwise by at most ``gamma_{2n+3} (c |P| + |E'| |Q| |E|)``
    (standard model, any summation order, ``c >= 0``); its Frobenius norm, doubled to cover
    its own rounding, is the ``err`` of :func:`_pd_proved`, which decides.

    Returns
    -------
    (bool, float)
        Proved (then even ``> 0``), and the slack ``lambda_min(H)`` less the allowance.
    """
    Q = P if Q is None else Q
    n = P.shape[0]
    H = c * P - (E.T @ Q) @ E
    aE = np.abs(E)
    bound = c * np.abs(P) + aE.T @ np.abs(Q) @ aE
    err = 2.0 * gamma(2 * n + 3) * float(np.linalg.norm(bound))
    return _pd_proved(H, err)


def _proved_all(P: np.ndarray, Phis: Sequence[np.ndarray], rho: float) -> tuple[bool, float]:
    """``P > 0`` and ``rho^2 P - Phi_j' P Phi_j >= 0`` for every j, proved (:func:`lmi_proved`).

    ``c = fl(rho rho) (1 - 4u)`` is below the exact ``rho^2``, so ``c P <= rho^2 P`` and the
    proof at ``c`` holds at ``rho``. Returns (proved, smallest informational slack).
    """
    ok, worst = _pd_proved(P, 0.0)
    if not ok:
        return False, worst
    c = (rho * rho) * (1.0 - 4.0 * UNIT_ROUNDOFF)
    for Phi in Phis:
        proved, slack = lmi_proved(c, P, Phi)
        ok, worst = ok and proved, min(worst, slack)
    return ok, worst


def common_lyapunov(Phis: Sequence[Any], *, rel_tol: float = 1e-5, margin: float = BACKOFF,
                    theta_max: float = 1e8, max_iter: int = 40) -> LyapunovCertificate:
    """Common quadratic Lyapunov function for cycle maps ``Phi_j`` (bisection on rho).

    ``cert = common_lyapunov([Phi_1, Phi_2, ...])``

    For fixed ``r`` the SDP

    .. math::

        \\min t \\quad P = P^T, \\quad I \\preceq P \\preceq t I, \\quad t \\le \\theta_{max}, \\quad
        \\Phi_j^T P \\Phi_j \\preceq r^2 P \\quad \\forall j

    is solved with Clarabel (``warm_start=False``): the best-conditioned ``P`` at ``r``.
    ``r`` is bisected between ``max_j rho(Phi_j)`` (no certificate below) and ``max_j
    ||Phi_j||`` (``P = I``). The SDP's edge is not used as the answer: a point there satisfies
    the LMI only up to the solver's tolerance (and an inaccurate solve near it may return an
    ill-conditioned ``P``). ``r`` counts as feasible only when the solver's ``P`` is *proved*
    (:func:`lmi_proved`: a Cholesky factorisation with an explicit rounding allowance) to
    satisfy the LMI at the backed-off rate ``r (1 + margin)``, where ``P`` is strictly
    interior (a relative gap of about ``2 margin`` in ``rho^2``). The reported ``rho`` is
    ``(1 + margin)`` times the smallest such ``r``: a proven upper bound whose proof does not
    rest on the solver's last digits, so it holds on every CPU. (On the paper's sequence
    (4 s, 0.5) (3 s, 0.6) (2 s, 0.4) the SDP's edge is ``r = 0.4953035`` with ``cond P =
    3.33``; ``rho = 0.49535``.)

    Parameters
    ----------
    Phis : sequence of (n, n) array_like
    rel_tol : float
        Relative width at which the bisection stops (the spread of ``rho`` between machines
        whose solvers decide a bisection point at the edge differently).
    margin : float
        Relative back-off of the certified rate from the SDP's edge (:data:`BACKOFF`).
    theta_max : float
        Upper bound on ``cond P`` (``I <= P <= theta_max I``).
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
    rho_lower = max(float(np.max(np.abs(np.linalg.eigvals(F)))) for F in Phis)
    lo = rho_lower
    best_P = np.eye(n)
    hi = _rate_of(best_P, Phis)
    P = cp.Variable((n, n), symmetric=True)
    t = cp.Variable()
    rho2 = cp.Parameter(nonneg=True)
    I = np.eye(n)
    cons = [P >> I, P << t * I, t <= theta_max]
    for F in Phis:
        S = rho2 * P - F.T @ P @ F
        cons.append(0.5 * (S + S.T) >> 0)
    prob = cp.Problem(cp.Minimize(t), cons)
    solves = 0
    for _ in range(max_iter):
        if hi - lo <= rel_tol * hi:
            break
        mid = 0.5 * (lo + hi)
        rho2.value = mid ** 2
        solves += 1
        if _solve_feasibility(prob) and P.value is not None:
            Pv = 0.5 * (P.value + P.value.T)
            if _proved_all(Pv, Phis, mid * (1 + margin))[0]:
                hi, best_P = mid, Pv
                continue
        lo = mid
    rho = hi * (1 + margin)
    verified, min_eig = _proved_all(best_P, Phis, rho)
    ev = np.linalg.eigvalsh(best_P)
    try:
        headroom = 1.0 - _rate_of(best_P, Phis) / rho
    except np.linalg.LinAlgError:
        headroom = -math.inf
    return LyapunovCertificate(rho=float(rho), rho_lower=min(rho_lower, float(rho)), P=best_P,
                               cond=float(ev[-1] / ev[0]), min_eig=min_eig,
                               verified=bool(verified), solves=solves, margin=float(headroom))
