"""Certificates: the paper's cycle factors beside sound, verified ones (Sections 4-6).

*The paper's certificate* (Theorem ``t:main``): per cycle the factors
``f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` (e:Fk, e:f11_le_delta_main) and the
claim ``||F_k|| <= delta < 1``. Its proof has a gap (DESIGN.md): while channel j is
active the observable error of channel i != j is also driven by ``-T_io' L_j C_j
x_tilde``, which (e:xo1_dynamics_piecewise) omits. The factors are reported as *the
paper's claim*; :func:`envelope_ratio` measures how far its envelopes are exceeded.

*Sound certificates* (ours, verified in floating point). They are for the paper's
continuous-output setting: products of ``expm((A - L_i C_i) h_i)``. A sampled observer with
innovation hold applies ``e^{A dt} - Gamma_A L C`` per sample instead, which equals
``expm((A - L C) dt)`` up to O(dt^2); measured on the paper's (2 s, 0.6) design the cycle
spectral radius is 0.4868 continuous, 0.4799 at 100 Hz and 0.4005 at 10 Hz, but these
certificates do not prove the sampled case.

* :func:`cycle_transition` -- the exact error map over one cycle,
  ``Phi = expm((A - L_N C_N) h_N) ... expm((A - L_1 C_1) h_1)`` (from
  e:xtilde_dyn_piecewise); a periodic schedule converges iff its spectral radius is < 1,
  and ``||x_tilde(t_{k+1})|| <= ||Phi|| ||x_tilde(t_k)||``.
* :func:`common_lyapunov` -- for a finite set of cycle types, ``P >= I`` with
  ``Phi_j' P Phi_j <= rho^2 P`` for all j, so ``||x_tilde(t_k)|| <= sqrt(cond P) rho^k
  ||x_tilde(0)||`` for *any* order of those cycles.
* :func:`certify_box` -- robust designs: every schedule with residence times in
  ``[h_min, h_max]`` (A2), proved with multiple Lyapunov functions and a rigorous
  remainder between grid points (the argument is in its docstring).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import expm

from .envelope import Segment, envelope_z, error_transitions
from .exceptions import InvalidArgument
from .schedule import PeriodicSchedule, SequenceSchedule
from .simulate import schedule_segments
from .validation import as_finite, as_matrix

__all__ = [
    "cycle_factor",
    "paper_factors",
    "cycle_transition",
    "CycleCertificate",
    "certify_cycle",
    "LyapunovCertificate",
    "common_lyapunov",
    "BoxCertificate",
    "certify_box",
    "EnvelopeRatio",
    "envelope_ratio",
    "certify_table",
    "format_report",
]


# ---------------------------------------------------------------------- the paper's
def cycle_factor(kappa: float, mu: float, eta: float, active: float, inactive: float) -> float:
    """The paper's cycle factor of one channel (e:Fk, e:f11_le_delta_main).

    ``f = kappa exp(mu (tau - h) - eta h)``: the channel decays at rate ``eta`` for its
    active time ``h`` and grows at most at rate ``mu`` for the rest of the cycle
    ``tau - h``; ``kappa`` is the overshoot of its observer (e:eta1_fixed).

    Parameters
    ----------
    kappa, mu, eta : float
        The channel's overshoot, growth bound and designed decay rate.
    active : float
        ``h``, the time the channel is active in the cycle (s).
    inactive : float
        ``tau - h``, the time it is inactive (s); for a robust design the worst case of
        the box, which need not equal ``tau - h`` of one cycle.

    Returns
    -------
    float
        ``kappa * exp(mu * inactive - eta * active)``; the single place this formula is
        evaluated.

    Raises
    ------
    InvalidArgument
        An argument is not a finite number, or a duration is negative.
    """
    for name, v in (("kappa", kappa), ("mu", mu), ("eta", eta), ("active", active), ("inactive", inactive)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v)) or (
                name in ("active", "inactive") and v < 0):
            raise InvalidArgument(f"cycle_factor: {name} must be a finite number (a duration >= 0); got {v!r}")
    return float(kappa * math.exp(mu * inactive - eta * active))


def paper_factors(design: Any, h: Sequence[float] | None = None) -> tuple[float, ...]:
    """The paper's cycle factors ``f_ii`` (e:Fk, e:f11_le_delta_main), N channels.

    ``f_i = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` with ``tau = sum h``.

    Parameters
    ----------
    design : CycleDesign
        Provides ``kappa``, ``eta``, ``mu`` (and ``cycle.h`` when ``h`` is None).
    h : sequence of float, optional
        Residence times ``h_1..h_N`` (default: the design's cycle).

    Returns
    -------
    tuple of float
        The paper claims convergence when every ``f_i < 1``: **not a proof** (module doc).
    """
    if h is None:
        if design.cycle is None:
            raise InvalidArgument("h is required for a design without a cycle (robust design)")
        h = design.cycle.h
    h = _residences(h, len(design.kappa), allow_zero=True)
    tau = float(sum(h))
    return tuple(cycle_factor(k, m, e, hi, tau - hi)
                 for k, m, e, hi in zip(design.kappa, design.mu, design.eta, h))


def _residences(h: Any, N: int, *, allow_zero: bool = False) -> tuple[float, ...]:
    """``h`` as N finite residence times > 0 (>= 0 with ``allow_zero``, tau > 0), or
    InvalidArgument naming ``h``."""
    try:
        hs = tuple(float(x) for x in h)
    except (TypeError, ValueError):
        raise InvalidArgument(f"h must be a sequence of {N} residence times; got {h!r}") from None
    ok = all(math.isfinite(x) and (x >= 0 if allow_zero else x > 0) for x in hs) and sum(hs) > 0
    if len(hs) != N or not ok:
        raise InvalidArgument(f"h must hold {N} finite residence times {'>= 0' if allow_zero else '> 0'}; "
                              f"got {hs}")
    return hs


# ---------------------------------------------------------------------- exact cycle map
def cycle_transition(A: Any, C: Sequence[Any], L: Sequence[Any], h: Sequence[float]) -> np.ndarray:
    """Exact error transition over one cycle (e:xtilde_dyn_piecewise).

    ``Phi = expm((A - L_N C_N) h_N) @ ... @ expm((A - L_1 C_1) h_1)``.

    Parameters
    ----------
    A : (n, n) array_like
    C : sequence of (p_i, n) array_like
    L : sequence of (n, p_i) array_like
        Embedded gains ``L_i = T_i [L_o^(i); 0]`` (e:L_original).
    h : sequence of float
        Residence times in channel order 1..N.

    Returns
    -------
    (n, n) ndarray
    """
    A = as_matrix(A, "A", square=True)
    n = A.shape[0]
    if not (len(C) == len(L) == len(h)):
        raise InvalidArgument(f"C, L and h must have one entry per channel; got {len(C)}, {len(L)}, {len(h)}")
    h = _residences(h, len(C))
    C = [as_matrix(Ci, f"C_{i + 1}", cols=n) for i, Ci in enumerate(C)]
    L = [as_matrix(Li, f"L_{i + 1}", rows=n, cols=Ci.shape[0]) for i, (Li, Ci) in enumerate(zip(L, C))]
    Phi = np.eye(n)
    for Ci, Li, hi in zip(C, L, h):
        Phi = expm((A - Li @ Ci) * hi) @ Phi
    return Phi


@dataclass(frozen=True)
class CycleCertificate:
    """The paper's factors and the exact cycle map of one (design, cycle) pair.

    Attributes
    ----------
    h : tuple of float
        Residence times certified.
    f : tuple of float
        The paper's factors (claim).
    paper_ok : bool
        ``max f < 1``: what Theorem ``t:main`` would conclude (not a proof).
    Phi : (n, n) ndarray
        Exact cycle transition.
    spectral_radius, norm : float
        ``rho(Phi)`` (< 1 iff the periodic schedule converges) and ``||Phi||_2``
        (< 1: monotone decrease of ``||x_tilde||`` at cycle ends).
    """

    h: tuple
    f: tuple
    paper_ok: bool
    Phi: np.ndarray
    spectral_radius: float
    norm: float

    @property
    def sound_ok(self) -> bool:
        """Spectral radius < 1 (convergence of the periodic schedule; verified)."""
        return self.spectral_radius < 1.0


def certify_cycle(system: Any, design: Any, h: Sequence[float] | None = None) -> CycleCertificate:
    """:class:`CycleCertificate` of ``design`` on residence times ``h`` (default its cycle)."""
    if h is None:
        if design.cycle is None:
            raise InvalidArgument("h is required for a robust design")
        h = design.cycle.h
    h = _residences(h, len(system.C))
    f = paper_factors(design, h)
    Phi = cycle_transition(system.A, system.C, design.L, h)
    return CycleCertificate(h=h, f=f, paper_ok=max(f) < 1, Phi=Phi,
                            spectral_radius=float(np.max(np.abs(np.linalg.eigvals(Phi)))),
                            norm=float(np.linalg.norm(Phi, 2)))


# ---------------------------------------------------------------------- common Lyapunov
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


# ---------------------------------------------------------------------- residence-time box
@dataclass(frozen=True)
class BoxCertificate:
    """Certificate over every schedule with residence times in ``[h_min, h_max]``.

    Attributes
    ----------
    h_min, h_max : float
    c : tuple of float
        Verified ``c_i >= sup_h lambda_max(P_i^{-1} E_i(h)' P_{i+1} E_i(h))``.
    rho : float
        ``sqrt(prod c_i)``: per cycle, ``V_1(x_tilde) = x_tilde' P_1 x_tilde`` at channel-1
        starts contracts at least by ``rho^2``.
    P : tuple of (n, n) ndarray
    cells : int
        Grid cells per channel in the verification.
    grid_rho : float
        The same product evaluated on the grid points only (no remainder).
    ok : bool
        ``rho < 1``: proved for every admissible schedule (cyclic order 1..N).
    """

    h_min: float
    h_max: float
    c: tuple
    rho: float
    P: tuple
    cells: int
    grid_rho: float
    cond: float = 1.0

    @property
    def ok(self) -> bool:
        return self.rho < 1.0


def _expm_grid(Lam: np.ndarray, hs: np.ndarray, block: int = 64) -> np.ndarray:
    """``expm(Lam h)`` on an equispaced grid: exact expm every ``block`` points, products between.

    Between anchors ``E(h_{a+j}) = E(h_a) S^j`` with ``S = expm(Lam d)``; the rounding of
    at most ``block`` products is far below the 1e-10 relative slack of the verification.
    """
    G = hs.size
    if G == 1:
        return expm(Lam * hs[0])[None]
    d = hs[1] - hs[0]
    S = expm(Lam * d)
    anchors = hs[::block]
    out = np.empty((G, Lam.shape[0], Lam.shape[0]))
    Ea = np.stack([expm(Lam * h) for h in anchors])
    out[::block] = Ea
    cur = Ea
    for j in range(1, block):
        cur = cur @ S
        idx = np.arange(j, G, block)
        out[idx] = cur[: idx.size]
    return out


def _box_verify(Lams, Ps, h_min, h_max, cells):
    """Rigorous upper bound of sup_h ||R_{i+1} E_i(h) R_i^{-1}|| per channel (see certify_box)."""
    N = len(Lams)
    Rs = [np.linalg.cholesky(P).T for P in Ps]
    Rinv = [np.linalg.inv(R) for R in Rs]
    hs = np.linspace(h_min, h_max, cells + 1)
    d = (h_max - h_min) / cells if cells else 0.0
    bounds, grid = [], []
    for i in range(N):
        Lam = Lams[i]
        Rn, Ri = Rs[(i + 1) % N], Rinv[i]
        E = _expm_grid(Lam, hs)
        S = np.linalg.norm(Rn[None] @ E @ Ri[None], 2, axis=(1, 2))
        En = np.linalg.norm(E, 2, axis=(1, 2))
        gain = np.linalg.norm(Rn, 2) * np.linalg.norm(Ri, 2)
        growth = math.expm1(np.linalg.norm(Lam, 2) * d)
        # cell [h_g, h_g + d]: ||R E(h) R^-1|| <= S_g + gain ||E(h_g)|| (e^{||Lam|| d} - 1)
        cell = S[:-1] + gain * En[:-1] * growth
        slack = 1e-10 * gain * En.max() + 1e-10 * S.max()
        b = float(max(cell.max() if cells else S.max(), S[-1])) + slack
        bounds.append(b * b)
        grid.append(float(S.max()) ** 2)
    return bounds, grid


def certify_box(system: Any, design: Any, h_min: float | None = None, h_max: float | None = None,
                *, coarse: int = 5, cells: int = 400, max_cells: int = 25600,
                theta_max: float = 1e6, rel_tol: float = 2e-2,
                gap: float = 0.02) -> BoxCertificate:
    """Certificate for every schedule with residence times in ``[h_min, h_max]`` (A2).

    Argument (multiple Lyapunov functions, channels in cyclic order 1..N). Let
    ``Lambda_i = A - L_i C_i``, ``E_i(h) = expm(Lambda_i h)`` and ``P_1..P_N > 0``,
    ``P_{N+1} = P_1``, ``P_i = R_i' R_i``. If for every ``h`` in the box

    .. math::  E_i(h)^T P_{i+1} E_i(h) \\preceq c_i P_i ,

    then ``V_i(x) = x' P_i x`` taken at the start of channel i's interval obeys
    ``V_{i+1} <= c_i V_i``, so over any cycle ``V_1(t_{k+1}) <= (prod_i c_i) V_1(t_k)``
    whatever the residence times in the box: with ``rho^2 = prod c_i < 1`` the error
    decays for *every* admissible schedule (any sequence of cycles), and
    ``||x_tilde(t_k)|| <= sqrt(cond P_1) rho^k ||x_tilde(0)||``.

    The ``P_i`` are found by an LMI on a coarse grid of ``h`` (common ``c``, bisected;
    a common ``c`` loses nothing since rescaling the ``P_i`` redistributes the ``c_i``
    at a fixed product). The grid is not the proof. The proof is the verification:
    ``sqrt(c_i(h)) = ||R_{i+1} E_i(h) R_i^{-1}||``, and for ``h`` in a cell
    ``[h_g, h_g + d]``, ``E_i(h) = E_i(h_g) expm(Lambda_i (h - h_g))`` so

    .. math::  \\|E_i(h) - E_i(h_g)\\| \\le \\|E_i(h_g)\\| (e^{\\|\\Lambda_i\\| d} - 1),

    hence ``sqrt(c_i(h)) <= ||R_{i+1} E_i(h_g) R_i^{-1}|| + ||R_{i+1}|| ||R_i^{-1}||
    ||E_i(h_g)|| (e^{||Lambda_i|| d} - 1)`` on the whole cell. The maximum over cells
    (plus a 1e-10 relative slack for rounding in expm, the grid products and the norms) is a bound on
    ``sup_h c_i(h)`` over the closed box. Cells are refined (x4) while the bound exceeds
    the grid-only value by more than ``gap`` (relative), up to ``max_cells``.

    Parameters
    ----------
    system : LTISystem
    design : CycleDesign
        The robust design (``h_bounds`` used when ``h_min``/``h_max`` are None).
    h_min, h_max : float, optional
    coarse : int
        Grid points per channel in the LMI.
    cells, max_cells : int
        Initial and largest number of verification cells per channel.
    theta_max : float
        ``I <= P_i <= theta_max I`` in the LMI.
    rel_tol : float
        Relative width at which the bisection on ``c`` stops (the LMI only proposes
        the ``P_i``; the verification decides).
    gap : float
        Refinement target of the verification (see above).

    Returns
    -------
    BoxCertificate
    """
    import cvxpy as cp

    if h_min is None or h_max is None:
        hb = getattr(design, "h_bounds", None)
        if hb is None:
            raise InvalidArgument("h_min and h_max are required (the design has no h_bounds)")
        h_min, h_max = hb
    h_min, h_max = as_finite(h_min, "h_min"), as_finite(h_max, "h_max")
    if not (0 < h_min <= h_max):
        raise InvalidArgument(f"need 0 < h_min <= h_max; got h_min = {h_min}, h_max = {h_max}")
    A = np.asarray(system.A, dtype=float)
    n = A.shape[0]
    Lams = [A - np.asarray(Li, float) @ np.asarray(Ci, float) for Li, Ci in zip(design.L, system.C)]
    N = len(Lams)
    hs = np.linspace(h_min, h_max, max(coarse, 2)) if h_max > h_min else np.array([h_min])
    Es = [[expm(L * h) for h in hs] for L in Lams]
    Pv = [cp.Variable((n, n), symmetric=True) for _ in range(N)]
    c = cp.Parameter(nonneg=True)
    I = np.eye(n)
    # scale each E so the LMI is well conditioned: constraints are homogeneous in E
    cons = [X >> I for X in Pv] + [X << theta_max * I for X in Pv]
    for i in range(N):
        for E in Es[i]:
            S = c * Pv[i] - E.T @ Pv[(i + 1) % N] @ E
            cons.append(0.5 * (S + S.T) >> 0)
    prob = cp.Problem(cp.Minimize(0), cons)
    # bracket: with P_i = I, c = max ||E||^2 is feasible
    hi = max(float(np.linalg.norm(E, 2)) ** 2 for Ei in Es for E in Ei)
    lo = 0.0
    best = [np.eye(n) for _ in range(N)]
    for _ in range(60):
        if hi - lo <= rel_tol * hi:
            break
        mid = 0.5 * (lo + hi)
        c.value = mid
        if _solve_feasibility(prob):
            cand = [0.5 * (X.value + X.value.T) for X in Pv]
            try:
                for X in cand:
                    np.linalg.cholesky(X)
            except np.linalg.LinAlgError:
                lo = mid
                continue
            hi = mid
            best = cand
        else:
            lo = mid
    ncell = cells
    while True:
        b, g = _box_verify(Lams, best, h_min, h_max, ncell)
        rho = math.sqrt(math.prod(b))
        grid_rho = math.sqrt(math.prod(g))
        if grid_rho >= 1 or ncell >= max_cells or (rho < 1 and rho <= grid_rho * (1 + gap)):
            break
        ncell *= 4
    ev = np.linalg.eigvalsh(best[0])
    return BoxCertificate(h_min=h_min, h_max=h_max, c=tuple(b), rho=rho, P=tuple(best),
                          cells=ncell, grid_rho=grid_rho, cond=float(ev[-1] / ev[0]))


# ---------------------------------------------------------------------- envelope ratio
@dataclass(frozen=True)
class EnvelopeRatio:
    """Worst case of ``||x_tilde_o^(i)(t)|| / z_i(t)`` over initial errors, per channel.

    Attributes
    ----------
    ratio : tuple of float
        ``max_t sigma_max(T_io' Phi(t, 0)) / (z_i(t) / z_i(0))``; > 1 means the paper's
        envelope z_i is exceeded by some initial error (the proof gap).
    t : tuple of float
        Time of the maximum.
    x0 : tuple of ndarray
        The unit initial error attaining it (top right singular vector).
    """

    ratio: tuple
    t: tuple
    x0: tuple
    horizon: float = 0.0


def envelope_ratio(system: Any, segments: Sequence[Segment], t_end: float, *,
                   dt: float = 0.002) -> EnvelopeRatio:
    """Worst-case excess of the paper's per-channel envelopes (the proof gap, DESIGN.md).

    With ``z_i(0^-) = ||x_tilde(0)||`` (the initial error bound), ``z_i(t) = g_i(t)
    ||x_tilde(0)||`` with ``g_i`` from (e:z1_evolution, e:z2_evolution), and
    ``x_tilde_o^(i)(t) = T_io' Phi(t, 0) x_tilde(0)`` exactly (continuous outputs). So

    .. math::

        \\max_{x_0 \\ne 0} \\frac{\\|T_{io}^T \\Phi(t,0) x_0\\|}{z_i(t)}
        = \\frac{\\sigma_{max}(T_{io}^T \\Phi(t, 0))}{g_i(t)},

    attained by the top right singular vector. The maximum is taken over a grid of
    step ``dt`` plus the switching instants, so the reported value is attained (a
    lower bound of the supremum over t). (With the tighter start ``z_i(0) =
    ||x_tilde_o^(i)(0)||`` the ratio is unbounded whenever ``T_io' L_j C_j x0 != 0`` for
    some ``x0`` in the unobservable subspace of channel i: ``z_i`` stays 0 while the other
    channel's correction pushes the error into channel i's observable subspace. The
    least-norm gains of our design happen not to couple that way on the paper's model.)

    Parameters
    ----------
    system : LTISystem
    segments : sequence of Segment
        The switching signal and designs (e.g. from
        :func:`switchobs_core.simulate.schedule_segments`).
    t_end : float
    dt : float

    Returns
    -------
    EnvelopeRatio
    """
    segments = list(segments)
    if not segments:
        raise InvalidArgument("segments: need at least one Segment")
    t0 = segments[0].t0
    t_end = as_finite(t_end, "t_end")
    if t_end <= t0:
        raise InvalidArgument(f"t_end must be > the first segment's start {t0}; got {t_end}")
    dt = as_finite(dt, "dt")
    if dt <= 0:
        raise InvalidArgument(f"dt must be > 0; got {dt}")
    grid = np.union1d(t0 + dt * np.arange(int((t_end - t0) / dt) + 1),
                      [s.t0 for s in segments if s.t0 <= t_end])
    Phis = error_transitions(system.A, system.C, grid, segments)
    g = envelope_z(grid, segments, 1.0)
    ratios, times, dirs = [], [], []
    for i in range(len(system.C)):
        T_o = system.decomposition(i + 1).T_o
        sv = np.linalg.norm(T_o.T[None] @ Phis, 2, axis=(1, 2))
        r = sv / g[i]
        k = int(np.argmax(r))
        _, _, Vt = np.linalg.svd(T_o.T @ Phis[k])
        ratios.append(float(r[k]))
        times.append(float(grid[k]))
        dirs.append(Vt[0])
    return EnvelopeRatio(ratio=tuple(ratios), t=tuple(times), x0=tuple(dirs), horizon=float(t_end))


# ---------------------------------------------------------------------- whole table
@dataclass
class TableReport:
    """Paper's and sound certificates for every design of a table (``switchobs certify``)."""

    designs: list = field(default_factory=list)
    sequence: dict | None = None
    robust: dict | None = None

    def to_dict(self) -> dict:
        return {"designs": self.designs, "sequence": self.sequence, "robust": self.robust}


def _cycle_entry(system, design, cert: CycleCertificate, ratio: EnvelopeRatio | None) -> dict:
    return {
        "cycle": design.cycle.label() if design.cycle is not None else "robust",
        "h": list(cert.h),
        "eta": list(design.eta),
        "kappa": list(design.kappa),
        "paper": {"f": list(cert.f), "claims_convergence": cert.paper_ok,
                  "status": "the paper's claim (proof has a gap; not verified)"},
        "sound": {"spectral_radius": cert.spectral_radius, "norm": cert.norm,
                  "converges": cert.sound_ok,
                  "status": "verified (exact cycle transition, floating point)"},
        "envelope_ratio": None if ratio is None else {
            "worst": list(ratio.ratio), "t": list(ratio.t), "horizon": ratio.horizon,
            "exceeded": [r > 1 for r in ratio.ratio]},
    }


def certify_table(system: Any, table: Any, *, sequence: Sequence[Any] | None = None,
                  ratio_cycles: int = 5, ratio_dt: float = 0.002, box: bool = True) -> TableReport:
    """Certify every design of ``table`` (and a cycle sequence, and the robust design).

    Per design: the paper's factors, the exact cycle map's spectral radius and norm,
    and the worst envelope ratio over ``ratio_cycles`` periodic cycles. With
    ``sequence`` (a list of Cycles, each looked up in the table): the paper's factors of
    each, a common quadratic Lyapunov function for their cycle maps (any order), and the
    envelope ratio over the repeated sequence. For ``table.robust``: the box certificate.
    """
    if not isinstance(ratio_cycles, (int, np.integer)) or ratio_cycles < 1:
        raise InvalidArgument(f"ratio_cycles must be an integer >= 1; got {ratio_cycles!r}")
    if as_finite(ratio_dt, "ratio_dt") <= 0:
        raise InvalidArgument(f"ratio_dt must be > 0; got {ratio_dt}")
    rep = TableReport()
    for d in table.designs:
        cert = certify_cycle(system, d)
        sched = PeriodicSchedule(d.cycle)
        t_end = ratio_cycles * d.cycle.tau
        ratio = envelope_ratio(system, schedule_segments(sched, [d], t_end), t_end, dt=ratio_dt)
        rep.designs.append(_cycle_entry(system, d, cert, ratio))
    if sequence:
        designs = [table.lookup(c) for c in sequence]
        certs = [certify_cycle(system, d, c.h) for d, c in zip(designs, sequence)]
        lyap = common_lyapunov([c.Phi for c in certs])
        sched = SequenceSchedule(list(sequence))
        t_end = ratio_cycles * sum(c.tau for c in sequence) / max(len(sequence), 1) * 2
        ratio = envelope_ratio(system, schedule_segments(sched, designs, t_end), t_end, dt=ratio_dt)
        rep.sequence = {
            "cycles": [c.label() for c in sequence],
            "paper": {"f": [list(c.f) for c in certs],
                      "claims_convergence": all(c.paper_ok for c in certs),
                      "status": "the paper's claim (not verified)"},
            "sound": {"cycle_spectral_radius": [c.spectral_radius for c in certs],
                      "cycle_norm": [c.norm for c in certs],
                      "common_lyapunov_rho": lyap.rho, "rho_lower": lyap.rho_lower,
                      "cond_P": lyap.cond, "min_eig": lyap.min_eig,
                      "verified": lyap.verified, "converges_any_order": lyap.ok,
                      "status": "verified (LMI solution re-checked in floating point)"},
            "envelope_ratio": {"worst": list(ratio.ratio), "t": list(ratio.t),
                               "horizon": ratio.horizon},
        }
    if box and getattr(table, "robust", None) is not None:
        d = table.robust
        bc = certify_box(system, d)
        hmin, hmax = bc.h_min, bc.h_max
        worst_h = [hmin if i == 0 else hmax for i in range(len(system.C))]
        f_worst = [paper_factors(d, [hmin if j == i else hmax for j in range(len(system.C))])[i]
                   for i in range(len(system.C))]
        rep.robust = {
            "h_bounds": [hmin, hmax],
            "eta": list(d.eta),
            "paper": {"f_worst": f_worst, "claims_convergence": max(f_worst) < 1,
                      "status": "the paper's claim at the worst corner (not verified)"},
            "sound": {"rho": bc.rho, "c": list(bc.c), "grid_rho": bc.grid_rho,
                      "cells": bc.cells, "cond_P1": bc.cond, "converges_all_schedules": bc.ok,
                      "status": "verified over the whole box (grid + rigorous remainder)"},
            "worst_h_example": worst_h,
        }
    return rep


def format_report(rep: TableReport) -> str:
    """Plain-text side-by-side rendering of a :class:`TableReport`."""
    lines = []
    hdr = (f"{'cycle':<16} {'eta':<16} {'paper f_ii (claim)':<24} {'paper says':<11} "
           f"{'rho(Phi)':>9} {'||Phi||':>9} {'verified':<9} {'env. ratio (worst)':<20}")
    lines.append("Per design: the paper's certificate (claim, proof has a gap) | sound certificate (verified)")
    lines.append(hdr)
    lines.append("-" * len(hdr))
    for e in rep.designs:
        f = ", ".join(f"{x:.4f}" for x in e["paper"]["f"])
        eta = ", ".join(f"{x:.3g}" for x in e["eta"])
        r = e["envelope_ratio"]
        rs = ", ".join(f"{x:.2f}" for x in r["worst"]) if r else "-"
        lines.append(f"{e['cycle']:<16} {eta:<16} {f:<24} "
                     f"{'converges' if e['paper']['claims_convergence'] else 'no claim':<11} "
                     f"{e['sound']['spectral_radius']:>9.4f} {e['sound']['norm']:>9.3f} "
                     f"{'yes' if e['sound']['converges'] else 'NO':<9} {rs:<20}")
    lines.append("env. ratio = max over initial errors and t of ||x_o^(i)(t)|| / z_i(t) "
                 "(> 1: the paper's envelope z_i is exceeded)")
    if rep.sequence:
        s = rep.sequence
        lines.append("")
        lines.append("Sequence " + " ".join(s["cycles"]) + " (any order of these cycle types):")
        lines.append("  paper (claim):  f_ii per cycle = " + "; ".join(
            ", ".join(f"{x:.4f}" for x in f) for f in s["paper"]["f"]))
        so = s["sound"]
        lines.append(f"  sound (verified): common Lyapunov rho = {so['common_lyapunov_rho']:.4f} per cycle "
                     f"(lower bound {so['rho_lower']:.4f}), cond(P) = {so['cond_P']:.3g}, "
                     f"verified = {so['verified']}, converges for any order = {so['converges_any_order']}")
        lines.append("  envelope ratio (worst) = " + ", ".join(f"{x:.2f}" for x in s["envelope_ratio"]["worst"]))
    if rep.robust:
        r = rep.robust
        lines.append("")
        lines.append(f"Robust design, residence times in [{r['h_bounds'][0]:g}, {r['h_bounds'][1]:g}] s:")
        lines.append("  paper (claim, worst corner): f_ii = " + ", ".join(f"{x:.4f}" for x in r["paper"]["f_worst"]))
        so = r["sound"]
        lines.append(f"  sound (verified over the whole box): rho = {so['rho']:.4f} per cycle "
                     f"(grid only {so['grid_rho']:.4f}, {so['cells']} cells/channel), "
                     f"converges for all schedules = {so['converges_all_schedules']}")
    return "\n".join(lines)
