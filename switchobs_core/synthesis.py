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
To leave room for solver tolerances the SDP is solved at eta_s = eta (1 + r) + 1e-7 for
the back-offs r = 1e-6, 1e-5, 1e-4, 1e-3 in turn, and the first gain that passes the check at
eta itself is returned (so the rate we state is the requested eta and it is verified; a
solver status ``optimal_inaccurate`` is accepted only through this check). The kappa we
report for a gain is sqrt(cond(P)) of the verified P (>= kappa*(eta) by a hair), never
the solver's theta.

Conditioning. Written as above, the LMI has coefficients of size ||A|| + eta, and at the
large rates a short active time needs (eta in the hundreds, theta* ~ 4 eta^2) solvers
stall at the edge of feasibility, with outcomes that differ between CPUs. We solve the
equivalent LMI divided by s = ||A|| + ||C|| + eta + 1,

    a (A'P + PA - C'Y' - YC) + b P <= 0,   a = 1/s,  b = 2 eta / s,

with a and b cvxpy Parameters (the problem is DPP: :meth:`LMISynthesizer.is_dpp`). If
that form fails (no solution, or a gain that fails verification), the same problem is
solved in the state scaling x = D x~, D = diag(d), d_i = sqrt(min_j P_jj / P_ii) from
the P of the plain form at eta, eta/2, ..., eta/32 in turn (:class:`_ScaledSDP`). It is an
exact change of variables, so theta* is unchanged; the least-norm rule is then applied to
the scaled (Pt, Yt), and the gain is verified in the original coordinates like any other.

Solver chain (fixed order, no warm starts): the chosen solver, then the other one
(Clarabel with defaults; SCS with eps 1e-9 and up to 2e4 iterations).

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from .decomposition import spectral_abscissa
from .exceptions import DesignError, InvalidArgument, VerificationError
from .validation import as_finite, as_matrix

__all__ = ["GainSynthesis", "LMISynthesizer", "KappaCurve", "verify_gain", "THETA_SLACK", "KAPPA_GRID", "ETA_BACKOFFS"]

#: Relative slack on theta* in the least-norm gain selection (kappa grows by <= 5e-5).
THETA_SLACK = 1e-4
#: Relative back-offs of the SDP's rate above the requested eta, tried in order (see gain()).
ETA_BACKOFFS = (1e-6, 1e-5, 1e-4, 1e-3)
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


class _ScaledSDP:
    """The two SDPs of the gain rule in the state scaling x = D x~ (D = diag(d) > 0, fixed).

    With P = D^-1 Pt D^-1 and Y = D^-1 Yt the LMI e:SDP_1 multiplied by D on both sides is
    At'Pt + Pt At - Ct'Yt' - Yt Ct + 2 eta Pt <= 0 with At = D^-1 A D, Ct = C D, and
    I <= P <= theta I reads D^2 <= Pt <= theta D^2: the same problem, better scaled
    variables. The LMI is further divided by s = ||At|| + ||Ct|| + eta + 1 through the
    Parameters a = 1/s, b = 2 eta / s (DPP).
    """

    def __init__(self, A: np.ndarray, C: np.ndarray, d: np.ndarray) -> None:
        import cvxpy as cp

        r, p = A.shape[0], C.shape[0]
        self.d = d
        At = (A * d[None, :]) / d[:, None]
        Ct = C * d[None, :]
        D2 = np.diag(d**2)
        self.norm = float(np.linalg.norm(At, 2)) + float(np.linalg.norm(Ct, 2))
        self.a = cp.Parameter(nonneg=True, name="a")
        self.b = cp.Parameter(nonneg=True, name="b")
        self.theta_cap = cp.Parameter(nonneg=True, name="theta_cap")
        self.P = cp.Variable((r, r), symmetric=True, name="P_scaled")
        self.Y = cp.Variable((r, p), name="Y_scaled")
        self.theta = cp.Variable(name="theta")
        M = self.a * (At.T @ self.P + self.P @ At - Ct.T @ self.Y.T - self.Y @ Ct) + self.b * self.P
        base = [0.5 * (M + M.T) << 0, self.P >> D2, self.P << self.theta * D2]
        self.stage1 = cp.Problem(cp.Minimize(self.theta), base)
        # least-norm rule in the scaled variables (the original ones when d = 1): measured in
        # the original coordinates the objective is as badly scaled as P itself.
        self.stage2 = cp.Problem(
            cp.Minimize(cp.norm(cp.hstack([self.P, self.Y]), "fro")), base + [self.theta <= self.theta_cap]
        )

    def set_eta(self, eta: float) -> None:
        scale = self.norm + eta + 1.0
        self.a.value = 1.0 / scale
        self.b.value = 2.0 * eta / scale

    def point(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(P, Y) in the original coordinates, or None if the solver returned no point."""
        if self.P.value is None or self.Y.value is None:
            return None
        P = np.asarray(self.P.value, dtype=float) / np.outer(self.d, self.d)
        Y = np.asarray(self.Y.value, dtype=float) / self.d[:, None]
        return (P + P.T) / 2, Y


def _scaling_from(P: np.ndarray) -> np.ndarray | None:
    """Diagonal scaling d = sqrt(min_j P_jj / P_ii) that equilibrates P's diagonal (or None)."""
    diag = np.diag(P)
    if not (np.all(np.isfinite(diag)) and np.all(diag > 0)):
        return None
    d = np.sqrt(diag.min() / diag)
    return None if np.allclose(d, 1.0, rtol=1e-2) else d


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
        self.A = as_matrix(A, "A_o", square=True)
        self.C = as_matrix(C, "C_o", cols=self.A.shape[0])
        solver = solver.upper()
        if solver not in ("CLARABEL", "SCS"):
            raise InvalidArgument(f"solver must be 'CLARABEL' or 'SCS'; got {solver!r}")
        self.solvers = [solver] + [s for s in ("CLARABEL", "SCS") if s != solver]
        self._plain = _ScaledSDP(self.A, self.C, np.ones(self.A.shape[0]))
        self.n_solves = 0

    def is_dpp(self) -> bool:
        """Both SDPs follow cvxpy's DPP rules (re-solves at a new eta reuse the canonicalisation)."""
        f = self._plain
        return bool(f.stage1.is_dcp(dpp=True) and f.stage2.is_dcp(dpp=True))

    def _attempts(self) -> list[tuple[str, dict]]:
        """(solver name, options) in the fixed fallback order; never warm-started."""
        opts = {"CLARABEL": {}, "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 20_000}}
        return [(s, opts[s]) for s in self.solvers]

    def _solve(self, prob, what: str, *, accept_inaccurate: bool = False, only_first: bool = False) -> str:
        """Solve ``prob`` with the first solver of the fallback chain that succeeds.

        ``optimal`` is accepted; ``optimal_inaccurate`` only when ``accept_inaccurate``
        (the caller then verifies the result in floating point), and then from the first
        solver that reports it (later solvers are not preferred over an earlier one).
        """
        import cvxpy as cp

        last = "not attempted"
        for s, opts in self._attempts()[: 1 if only_first else None]:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    prob.solve(solver=s, warm_start=False, **opts)
            except cp.error.SolverError as err:
                last = f"{s}: {err}"
                continue
            finally:
                self.n_solves += 1
            if prob.status == cp.OPTIMAL or (prob.status == cp.OPTIMAL_INACCURATE and accept_inaccurate):
                return s
            last = f"{s}: status {prob.status}"
        raise DesignError(f"the SDP for {what} did not solve ({last})")

    def _theta(self, form: _ScaledSDP, eta: float, accept_inaccurate: bool) -> float:
        form.set_eta(eta)
        self._solve(form.stage1, f"kappa(eta = {eta:.6g})", accept_inaccurate=accept_inaccurate)
        return float(form.theta.value)

    def _rescaled(self, eta: float):
        """Rescaled forms of the problem (see :class:`_ScaledSDP`), in a fixed order: state
        scalings that equilibrate the P of the plain form solved at eta, eta/2, ..., eta/32
        (those that return a point)."""
        f = self._plain
        for k in range(6):
            f.set_eta(eta / 2**k)
            try:
                self._solve(f.stage1, "scaling", accept_inaccurate=True, only_first=True)
            except DesignError:
                continue
            pt = f.point()
            d = None if pt is None else _scaling_from(pt[0])
            if d is not None:
                yield _ScaledSDP(self.A, self.C, d)

    def theta_star(self, eta: float, *, accept_inaccurate: bool = False) -> float:
        """theta*(eta), the optimal value of e:SDP_1-4 (kappa* = sqrt(theta*)).

        Solved in the plain form; if that fails, in the rescaled forms in their fixed
        order (:meth:`_rescaled`) until one solves.
        """
        eta = as_finite(eta, "eta")
        if eta < 0:
            raise InvalidArgument(f"eta must be >= 0; got {eta}")
        try:
            return self._theta(self._plain, eta, accept_inaccurate)
        except DesignError as err:
            first = err
        for form in self._rescaled(eta):
            try:
                return self._theta(form, eta, accept_inaccurate)
            except DesignError:
                continue
        raise first

    def gain(self, eta: float) -> GainSynthesis:
        """The verified least-norm gain at decay rate eta (rule in the module docstring).

        For each back-off r in :data:`ETA_BACKOFFS` in turn, the SDP is solved at
        eta_s = eta (1 + r) + 1e-7, first in the plain form and then in the rescaled ones;
        the first gain that passes the floating-point verification at eta itself is
        returned. Raises the last :class:`VerificationError` (or :class:`DesignError`)
        if none passes.
        """
        eta = as_finite(eta, "eta")
        if eta < 0:
            raise InvalidArgument(f"eta must be >= 0; got {eta}")
        last: DesignError | None = None
        for rel in ETA_BACKOFFS:
            eta_s = eta * (1 + rel) + _ETA_ABS_MARGIN
            for form in itertools.chain([self._plain], self._rescaled(eta_s)):
                try:
                    return self._gain_at(form, eta, eta_s)
                except DesignError as err:  # VerificationError is a DesignError
                    last = err
        assert last is not None
        raise type(last)(f"{last} (tried SDP back-offs {', '.join(f'{r:g}' for r in ETA_BACKOFFS)})") from None

    def _gain_at(self, form: _ScaledSDP, eta: float, eta_s: float) -> GainSynthesis:
        theta = self._theta(form, eta_s, True)
        form.theta_cap.value = theta * (1 + THETA_SLACK)
        solver = self._solve(form.stage2, f"the gain at eta = {eta:.6g}", accept_inaccurate=True)
        pt = form.point()
        if pt is None:
            raise DesignError(f"the SDP for the gain at eta = {eta:.6g} returned no point ({solver})")
        P, Y = pt
        try:
            L = np.linalg.solve(P, Y)
        except np.linalg.LinAlgError:
            raise VerificationError(f"the SDP at eta = {eta:.6g} returned a singular P") from None
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
            # optimal_inaccurate is accepted here: the curve only locates eta_min; every
            # gain and every factor f_ii is computed from a verified P (LMISynthesizer.gain).
            self.cache[eta] = math.sqrt(max(self.synthesizer.theta_star(eta, accept_inaccurate=True), 1.0))
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
