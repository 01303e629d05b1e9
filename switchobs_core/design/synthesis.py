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
of solves. Both problems are stated once per pair with eta as a parameter and solved
without warm start (Clarabel; SCS as fallback; see "Solver chain").

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

Solver chain (fixed order, no warm starts): Clarabel called directly on the conic form of
the problem (:meth:`_ScaledSDP.solve_conic`, Clarabel's defaults as cvxpy passes them), then
through cvxpy the chosen solver and the other one (Clarabel with defaults; SCS with eps 1e-9
and up to 2e4 iterations); with ``solver="SCS"`` SCS through cvxpy comes first. The direct call
is the same solver on the same problem without the modelling layer, whose import (about 1.5 s,
most of a `switchobs plan`) and per-solve overhead (twice the solve) it saves; on the paper's
model its theta* agrees with the cvxpy path to 1e-7 (relative) and eta_min to 1e-8.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field

import clarabel
import numpy as np
from numpy.typing import ArrayLike
from scipy import sparse

from ..exceptions import DesignError, InvalidArgument, VerificationError
from ..model.decomposition import spectral_abscissa
from ..validation import as_finite, as_matrix

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
            f"gain fails its Lyapunov certificate: checked in floating point, the solver's P certifies decay rate "
            f"{eta_v:.9g} < eta = {eta:.9g} 1/s asked for (the SDP at this rate is beyond what the solver resolves "
            "for this channel): ask for less (a larger --delta, a smaller --eta), or design Kalman gains "
            "(--gains kalman --rate HZ); docs/troubleshooting.md"
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

    Two equal statements of it (module docstring, "Solver chain"): the conic form handed to
    Clarabel directly (:meth:`_conic`: no modelling layer, no cvxpy import), and the cvxpy
    problems :attr:`stage1` and :attr:`stage2` (built on first use) for the fallbacks.
    Conic form: the variables are ``x = [svec(Pt), vec(Yt), theta(, t)]`` with ``svec`` the
    upper triangle column by column, off-diagonal entries times sqrt(2) (Clarabel's
    ``PSDTriangleConeT``; ``||svec(Pt)|| = ||Pt||_F``); each LMI ``S(x) >= 0`` is the cone row
    block ``s = b - A x = svec(S(x))``, and the least-norm objective of stage 2 is ``t`` with
    ``(t, svec(Pt), vec(Yt))`` in the second-order cone.
    """

    def __init__(self, A: np.ndarray, C: np.ndarray, d: np.ndarray) -> None:
        r, p = A.shape[0], C.shape[0]
        self.d = d
        self.At = (A * d[None, :]) / d[:, None]
        self.Ct = C * d[None, :]
        self.D2 = np.diag(d**2)
        self.norm = float(np.linalg.norm(self.At, 2)) + float(np.linalg.norm(self.Ct, 2))
        self.r, self.p = r, p
        self.a = self.b = 0.0
        self.theta_cap = 0.0
        self.theta_value: float | None = None
        self.point_value: tuple[np.ndarray, np.ndarray] | None = None
        self._cvx: tuple | None = None
        self._lmi: tuple[np.ndarray, np.ndarray] | None = None

    # -- the conic form ---------------------------------------------------------------------
    def _tri(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row, column and weight (1 on the diagonal, sqrt(2) off it) of each svec entry."""
        iu = np.triu_indices(self.r)
        order = np.lexsort((iu[0], iu[1]))            # column by column
        i, j = iu[0][order], iu[1][order]
        return i, j, np.where(i == j, 1.0, math.sqrt(2.0))

    def _svec(self, S: np.ndarray) -> np.ndarray:
        i, j, w = self._tri()
        return w * S[i, j]

    def _smat(self, v: np.ndarray) -> np.ndarray:
        """The symmetric matrix S with svec(S) = v (the inverse of :meth:`_svec`)."""
        i, j, w = self._tri()
        S = np.zeros((self.r, self.r))
        S[i, j] = v / w
        S[j, i] = v / w
        return S

    def _lmi_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Columns of the LMI's linear map per variable: ``G`` for ``At'Pt + Pt At - Ct'Yt' - Yt Ct``,
        ``H`` for ``Pt`` (so that the LMI block of the cone rows is ``a G + b H``)."""
        if self._lmi is None:
            r, p = self.r, self.p
            m = r * (r + 1) // 2
            G = np.zeros((m, m + r * p + 1))
            H = np.zeros((m, m + r * p + 1))
            for k in range(m):
                E = self._smat(np.eye(m)[k])
                G[:, k] = self._svec(self.At.T @ E + E @ self.At)
                H[:, k] = np.eye(m)[k]
            for k in range(r * p):
                F = np.zeros((r, p))
                F.flat[k] = 1.0
                G[:, m + k] = self._svec(-(self.Ct.T @ F.T + F @ self.Ct))
            self._lmi = (G, H)
        return self._lmi

    def _conic(self, stage: int) -> tuple:
        """``(P, q, A, b, cones)`` of stage 1 (min theta) or 2 (least norm, theta <= theta_cap)."""
        r, p = self.r, self.p
        m = r * (r + 1) // 2
        nv = m + r * p + 1 + (stage == 2)
        it = m + r * p                                   # index of theta
        G, H = self._lmi_maps()
        pad = np.zeros((m, nv - G.shape[1]))
        I_P = np.zeros((m, nv))
        I_P[:, :m] = np.eye(m)
        svec_D2 = self._svec(self.D2)
        # 1. -(a L(Pt, Yt) + b Pt) >= 0:  s = -svec(M) = b - A x with A = svec-map of M, b = 0
        A1 = np.hstack([self.a * G + self.b * H, pad])
        # 2. Pt - D^2 >= 0:  s = svec(Pt) - svec(D^2)
        A2, b2 = -I_P, -svec_D2
        # 3. theta D^2 - Pt >= 0:  s = theta svec(D^2) - svec(Pt)
        A3 = I_P.copy()
        A3[:, it] = -svec_D2
        blocks = [A1, A2, A3]
        rhs = [np.zeros(m), b2, np.zeros(m)]
        cones = [clarabel.PSDTriangleConeT(r)] * 3
        q = np.zeros(nv)
        if stage == 1:
            q[it] = 1.0
        else:
            # theta <= theta_cap;  (t, svec(Pt), vec(Yt)) in the second-order cone
            cap = np.zeros((1, nv))
            cap[0, it] = 1.0
            soc = np.zeros((1 + m + r * p, nv))
            soc[0, nv - 1] = -1.0
            soc[1:, :m + r * p] = -np.eye(m + r * p)
            blocks += [cap, soc]
            rhs += [np.array([self.theta_cap]), np.zeros(1 + m + r * p)]
            cones += [clarabel.NonnegativeConeT(1), clarabel.SecondOrderConeT(1 + m + r * p)]
            q[nv - 1] = 1.0
        A = sparse.csc_matrix(np.vstack(blocks))
        return sparse.csc_matrix((nv, nv)), q, A, np.concatenate(rhs), cones

    def solve_conic(self, stage: int) -> str:
        """Solve stage 1 or 2 with Clarabel directly (defaults, as cvxpy calls it); the status in
        cvxpy's words (``optimal``, ``optimal_inaccurate`` or another)."""
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        try:
            sol = clarabel.DefaultSolver(*self._conic(stage), settings).solve()
        except (ValueError, RuntimeError, TypeError) as err:   # data Clarabel refuses (e.g. not finite)
            self.theta_value = self.point_value = None
            return f"error ({err})"
        status = {"Solved": "optimal", "AlmostSolved": "optimal_inaccurate"}.get(str(sol.status), str(sol.status))
        self.theta_value = self.point_value = None
        if status in ("optimal", "optimal_inaccurate"):
            x = np.asarray(sol.x, dtype=float)
            m = self.r * (self.r + 1) // 2
            self.theta_value = float(x[m + self.r * self.p])
            self.point_value = (self._smat(x[:m]), x[m:m + self.r * self.p].reshape(self.r, self.p))
        return status

    # -- the cvxpy form (fallbacks, and the DPP check) ---------------------------------------
    @property
    def stage1(self):
        return self._cvxpy()[0]

    @property
    def stage2(self):
        return self._cvxpy()[1]

    def _cvxpy(self) -> tuple:
        if self._cvx is None:
            import cvxpy as cp

            r, p = self.r, self.p
            a = cp.Parameter(nonneg=True, name="a")
            b = cp.Parameter(nonneg=True, name="b")
            cap = cp.Parameter(nonneg=True, name="theta_cap")
            P = cp.Variable((r, r), symmetric=True, name="P_scaled")
            Y = cp.Variable((r, p), name="Y_scaled")
            theta = cp.Variable(name="theta")
            At, Ct = self.At, self.Ct
            M = a * (At.T @ P + P @ At - Ct.T @ Y.T - Y @ Ct) + b * P
            base = [0.5 * (M + M.T) << 0, P >> self.D2, P << theta * self.D2]
            stage1 = cp.Problem(cp.Minimize(theta), base)
            # least-norm rule in the scaled variables (the original ones when d = 1): measured in
            # the original coordinates the objective is as badly scaled as P itself.
            stage2 = cp.Problem(cp.Minimize(cp.norm(cp.hstack([P, Y]), "fro")), base + [theta <= cap])
            self._cvx = (stage1, stage2, a, b, cap, P, Y, theta)
        return self._cvx

    def solve_cvxpy(self, stage: int, solver: str, opts: dict) -> str:
        """Solve stage 1 or 2 through cvxpy with ``solver``; the status (raises cvxpy's SolverError)."""
        prob, _, a, b, cap, P, Y, theta = self._cvxpy()
        if stage == 2:
            prob = self._cvxpy()[1]
        a.value, b.value, cap.value = self.a, self.b, self.theta_cap
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(solver=solver, warm_start=False, **opts)
        self.theta_value = None if theta.value is None else float(theta.value)
        self.point_value = None if P.value is None or Y.value is None else (
            np.asarray(P.value, dtype=float), np.asarray(Y.value, dtype=float))
        return str(prob.status)

    def set_eta(self, eta: float) -> None:
        scale = self.norm + eta + 1.0
        self.a = 1.0 / scale
        self.b = 2.0 * eta / scale

    def point(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(P, Y) in the original coordinates, or None if the solver returned no point."""
        if self.point_value is None:
            return None
        Pt, Yt = self.point_value
        P = Pt / np.outer(self.d, self.d)
        Y = Yt / self.d[:, None]
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
        """(solver name, options) in the fixed fallback order; never warm-started. ``clarabel``
        (lower case) is Clarabel called directly on the conic form; the others go through cvxpy."""
        opts = {"CLARABEL": {}, "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 20_000}}
        chain = [(s, opts[s]) for s in self.solvers]
        return [("clarabel", {}), *chain] if self.solvers[0] == "CLARABEL" else [*chain[:1], ("clarabel", {}),
                                                                                *chain[1:]]

    def _solve(self, form: _ScaledSDP, stage: int, what: str, *, accept_inaccurate: bool = False,
               only_first: bool = False) -> str:
        """Solve stage 1 or 2 of ``form`` with the first solver of the fallback chain that succeeds.

        ``optimal`` is accepted; ``optimal_inaccurate`` only when ``accept_inaccurate``
        (the caller then verifies the result in floating point), and then from the first
        solver that reports it (later solvers are not preferred over an earlier one).
        """
        last = "not attempted"
        for s, opts in self._attempts()[: 1 if only_first else None]:
            try:
                if s == "clarabel":
                    status = form.solve_conic(stage)
                else:
                    import cvxpy as cp

                    try:
                        status = form.solve_cvxpy(stage, s, opts)
                    except cp.error.SolverError as err:
                        last = f"{s}: {err}"
                        continue
            finally:
                self.n_solves += 1
            if status == "optimal" or (status == "optimal_inaccurate" and accept_inaccurate):
                return s.upper()
            last = f"{s.upper()}: status {status}"
        raise DesignError(f"the SDP for {what} did not solve ({last})")

    def _theta(self, form: _ScaledSDP, eta: float, accept_inaccurate: bool) -> float:
        form.set_eta(eta)
        self._solve(form, 1, f"kappa(eta = {eta:.6g})", accept_inaccurate=accept_inaccurate)
        assert form.theta_value is not None
        return form.theta_value

    def _rescaled(self, eta: float):
        """Rescaled forms of the problem (see :class:`_ScaledSDP`), in a fixed order: state
        scalings that equilibrate the P of the plain form solved at eta, eta/2, ..., eta/32
        (those that return a point)."""
        f = self._plain
        for k in range(6):
            f.set_eta(eta / 2**k)
            try:
                self._solve(f, 1, "scaling", accept_inaccurate=True, only_first=True)
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
        form.theta_cap = theta * (1 + THETA_SLACK)
        solver = self._solve(form, 2, f"the gain at eta = {eta:.6g}", accept_inaccurate=True)
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
