"""LMI synthesis of the observer gain (Lemma ``t:observer-sdp-design``) and kappa curves.

For an observable pair (A, C) (in practice (A_o^(i), C_o^(i)) of one channel) and a
decay rate eta >= 0, the SDP

    min theta  s.t.  A'P + PA - C'Y' - YC + 2 eta P <= 0,   I <= P <= theta I   (e:SDP_1-4)

gives L = P^{-1} Y with ||e^{(A - LC) t}|| <= sqrt(theta) e^{-eta t} (e:error_bound).
kappa*(eta) = sqrt(theta*) depends on eta only and is non-decreasing in it (the
feasible set shrinks as eta grows).

Gain rule. The optimal (P, Y) is not unique (Y has an unbounded optimal ray), so solvers
return different gains with the same kappa. We pick the unique minimiser of
||[P, Y]||_F over the near-optimal set {theta <= (1 + THETA_SLACK) theta*}: a strictly
convex objective over a convex set, hence one answer whatever the solver or the order
of solves. Both problems are built once per pair with eta as a cvxpy Parameter and
solved with ``warm_start=False`` (Clarabel; SCS as fallback).

Verification. Every gain is checked in floating point before it is returned: with
Lambda = A - LC and the returned P, the generalized eigenvalue
lambda_max(P^{-1/2} (Lambda'P + P Lambda) P^{-1/2}) must be <= -2 eta (so
V = x'Px decays at rate 2 eta), and the spectral abscissa of Lambda must be < -eta.
To leave room for solver tolerances the SDP is solved at eta_s = eta (1 + 1e-6) + 1e-7,
and the gain is verified at eta. The kappa we report for a gain is
sqrt(cond(P)) of the verified P (>= kappa*(eta) by a hair), never the solver's theta.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .decomposition import spectral_abscissa
from .exceptions import DesignError, InvalidArgument, VerificationError
from .validation import as_finite, as_matrix

__all__ = ["GainSynthesis", "LMISynthesizer", "KappaCurve", "verify_gain", "THETA_SLACK", "KAPPA_GRID"]

#: Relative slack on theta* in the least-norm gain selection (kappa grows by <= 5e-5).
THETA_SLACK = 1e-4
_ETA_REL_MARGIN = 1e-6
_ETA_ABS_MARGIN = 1e-7


@dataclass(frozen=True)
class GainSynthesis:
    """A verified observer gain for one channel at decay rate eta.

    Attributes
    ----------
    eta : float
        The decay rate the gain is verified for.
    L_o : (r, p) ndarray
        Gain in observable coordinates (e:Lstar).
    P : (r, r) ndarray
        The Lyapunov matrix of the verification.
    kappa : float
        sqrt(cond(P)) of the verified P: ||e^{Lambda t}|| <= kappa e^{-eta t}.
    kappa_star : float
        sqrt(theta*) of the SDP at eta_s (the curve value).
    eta_verified : float
        The largest rate the returned (P, L) certifies: -lambda_max(P^-1/2 (Lambda'P + P Lambda) P^-1/2)/2.
    abscissa : float
        Spectral abscissa of Lambda = A - L C.
    solver : str
    """

    eta: float
    L_o: np.ndarray
    P: np.ndarray
    kappa: float
    kappa_star: float
    eta_verified: float
    abscissa: float
    solver: str


def verify_gain(A: ArrayLike, C: ArrayLike, L: ArrayLike, P: ArrayLike, eta: float) -> tuple[float, float, float]:
    """Floating-point check of the Lyapunov certificate of a gain.

    ``eta_v, kappa, abscissa = verify_gain(A, C, L, P, eta)``

    Returns the rate eta_v certified by P for Lambda = A - L C, kappa = sqrt(cond(P)),
    and the spectral abscissa of Lambda.

    Raises
    ------
    VerificationError
        P is not positive definite, eta_v < eta, or alpha(Lambda) >= -eta.
    """
    A = as_matrix(A, "A", square=True)
    n = A.shape[0]
    C = as_matrix(C, "C", cols=n)
    L = as_matrix(L, "L", rows=n, cols=C.shape[0])
    P = as_matrix(P, "P", rows=n, cols=n)
    eta = as_finite(eta, "eta")
    P = (P + P.T) / 2
    Lam = A - L @ C
    w, V = np.linalg.eigh(P)
    if w[0] <= 0:
        raise VerificationError(f"the Lyapunov matrix P is not positive definite (lambda_min = {w[0]:.3g})")
    Pm12 = (V / np.sqrt(w)) @ V.T
    S = Pm12 @ (Lam.T @ P + P @ Lam) @ Pm12
    lam = np.linalg.eigvalsh((S + S.T) / 2)[-1]
    # eigvalsh's backward error: a few n * eps * ||S||; count it against the certificate.
    lam += 8 * S.shape[0] * np.finfo(float).eps * max(np.linalg.norm(S, 2), 1.0)
    eta_v = -lam / 2
    ab = spectral_abscissa(Lam)
    if eta_v < eta:
        raise VerificationError(
            f"gain fails its Lyapunov certificate: P certifies decay rate {eta_v:.9g} < eta = {eta:.9g}"
        )
    if ab >= -eta:
        raise VerificationError(f"gain fails: spectral abscissa {ab:.6g} is not below -eta = {-eta:.6g}")
    return float(eta_v), float(math.sqrt(w[-1] / w[0])), float(ab)


class LMISynthesizer:
    """The SDP of Lemma ``t:observer-sdp-design`` for one observable pair, built once.

    ``syn = LMISynthesizer(A_o, C_o); theta = syn.theta_star(eta); g = syn.gain(eta)``

    Parameters
    ----------
    A : (r, r) array_like
    C : (p, r) array_like
    solver : str
        ``"CLARABEL"`` (default) or ``"SCS"``; the other is the fallback.
    """

    def __init__(self, A: ArrayLike, C: ArrayLike, *, solver: str = "CLARABEL") -> None:
        import cvxpy as cp

        self.A = as_matrix(A, "A_o", square=True)
        self.C = as_matrix(C, "C_o", cols=self.A.shape[0])
        solver = solver.upper()
        if solver not in ("CLARABEL", "SCS"):
            raise InvalidArgument(f"solver must be 'CLARABEL' or 'SCS'; got {solver!r}")
        self.solvers = [solver] + [s for s in ("CLARABEL", "SCS") if s != solver]
        r, p = self.A.shape[0], self.C.shape[0]
        I = np.eye(r)
        self._eta = cp.Parameter(nonneg=True, name="eta")
        self._theta_cap = cp.Parameter(nonneg=True, name="theta_cap")
        P = cp.Variable((r, r), symmetric=True, name="P")
        Y = cp.Variable((r, p), name="Y")
        theta = cp.Variable(name="theta")
        M = self.A.T @ P + P @ self.A - self.C.T @ Y.T - Y @ self.C + 2 * self._eta * P
        lyap = 0.5 * (M + M.T) << 0
        base = [lyap, P >> I, P << theta * I]
        self._P, self._Y, self._theta = P, Y, theta
        self._stage1 = cp.Problem(cp.Minimize(theta), base)
        self._stage2 = cp.Problem(cp.Minimize(cp.norm(cp.hstack([P, Y]), "fro")), base + [theta <= self._theta_cap])
        self.n_solves = 0

    def _solve(self, prob, what: str) -> str:
        import cvxpy as cp

        last = "not attempted"
        for s in self.solvers:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    prob.solve(solver=s, warm_start=False)
            except cp.error.SolverError as err:
                last = f"{s}: {err}"
                continue
            finally:
                self.n_solves += 1
            if prob.status == cp.OPTIMAL:
                return s
            last = f"{s}: status {prob.status}"
        raise DesignError(f"the SDP for {what} did not solve ({last})")

    def theta_star(self, eta: float) -> float:
        """theta*(eta), the optimal value of e:SDP_1-4 (kappa* = sqrt(theta*))."""
        eta = as_finite(eta, "eta")
        if eta < 0:
            raise InvalidArgument(f"eta must be >= 0; got {eta}")
        self._eta.value = eta
        self._solve(self._stage1, f"kappa(eta = {eta:.6g})")
        return float(self._theta.value)

    def gain(self, eta: float) -> GainSynthesis:
        """The verified least-norm gain at decay rate eta (rule in the module docstring)."""
        eta = as_finite(eta, "eta")
        if eta < 0:
            raise InvalidArgument(f"eta must be >= 0; got {eta}")
        eta_s = eta * (1 + _ETA_REL_MARGIN) + _ETA_ABS_MARGIN
        theta = self.theta_star(eta_s)
        self._eta.value = eta_s
        self._theta_cap.value = theta * (1 + THETA_SLACK)
        solver = self._solve(self._stage2, f"the gain at eta = {eta:.6g}")
        P = np.array(self._P.value, dtype=float)
        P = (P + P.T) / 2
        Y = np.array(self._Y.value, dtype=float)
        L = np.linalg.solve(P, Y)
        if not (np.all(np.isfinite(L)) and np.all(np.isfinite(P))):
            raise VerificationError(f"the SDP at eta = {eta:.6g} returned a non-finite gain")
        eta_v, kappa, ab = verify_gain(self.A, self.C, L, P, eta)
        return GainSynthesis(
            eta=eta,
            L_o=L,
            P=P,
            kappa=kappa,
            kappa_star=math.sqrt(theta),
            eta_verified=eta_v,
            abscissa=ab,
            solver=solver,
        )


#: Fixed eta grid of the kappa curves: {0} U {0.05 * 1.12^k}, up to about 1.4e4.
KAPPA_GRID = np.concatenate([[0.0], 0.05 * 1.12 ** np.arange(0, 111)])


@dataclass
class KappaCurve:
    """kappa_i(eta) = sqrt(theta*(eta)) of one channel, computed lazily and cached.

    kappa depends on eta only, not on the cycle (the SDP e:SDP_1 has no cycle in it), so one curve serves every
    design of the channel: a design over many cycles costs root-finding on cached
    values, not new SDPs. :meth:`kappa` is made non-decreasing (where the solver's last
    digits are not) by taking the max with the values at the fixed grid points
    :data:`KAPPA_GRID` below eta. It is a function of eta alone, whatever was solved
    before: no result depends on the order of solves.
    """

    synthesizer: LMISynthesizer
    cache: dict[float, float] = field(default_factory=dict)
    grid: np.ndarray = field(default_factory=lambda: KAPPA_GRID)
    #: prefix maxima of raw() over grid[0..j], filled left to right as far as needed
    _prefix: list[float] = field(default_factory=list, repr=False)

    def raw(self, eta: float) -> float:
        """kappa*(eta) from the SDP (cached)."""
        eta = float(eta)
        if eta not in self.cache:
            self.cache[eta] = math.sqrt(max(self.synthesizer.theta_star(eta), 1.0))
        return self.cache[eta]

    def kappa(self, eta: float) -> float:
        """Non-decreasing kappa(eta) = max(raw(eta), raw(g) for grid points g <= eta)."""
        eta = float(eta)
        j = int(np.searchsorted(self.grid, eta, side="right"))  # grid[:j] <= eta
        while len(self._prefix) < j:
            g = float(self.grid[len(self._prefix)])
            self._prefix.append(max(self.raw(g), self._prefix[-1]) if self._prefix else self.raw(g))
        val = self.raw(eta)
        return max(val, self._prefix[j - 1]) if j else val

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """The evaluated grid points (eta, kappa), sorted, monotone: the stored curve."""
        e = np.array([g for g in self.grid if float(g) in self.cache])
        if e.size == 0:
            return np.zeros(0), np.zeros(0)
        k = np.maximum.accumulate(np.array([self.cache[float(x)] for x in e]))
        return e, k
