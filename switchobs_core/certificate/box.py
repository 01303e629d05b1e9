"""Residence-time box proof: every schedule with residence times in ``[h_min, h_max]``
(assumption A2) converges, proved with multiple Lyapunov functions and a rigorous remainder
between grid points (the argument is in :func:`certify_box`'s docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..exceptions import InvalidArgument
from ..validation import as_finite
from .lyapunov import BACKOFF, _pd_proved, _solve_feasibility, lmi_proved

__all__ = ["BoxCertificate", "certify_box"]


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
    at a fixed product). A ``c`` counts as feasible only when the solver's ``P_i`` are
    proved (:func:`~.lyapunov.lmi_proved`, rounding included) positive definite and to satisfy
    the grid LMI at ``c (1 + BACKOFF)^2``: an inaccurate point at the SDP's edge is never
    used, so the ``P_i`` do not depend on the solver's last digits. The grid is not the proof.
    The proof is the verification: ``sqrt(c_i(h)) = ||R_{i+1} E_i(h) R_i^{-1}||``, and for ``h`` in a cell
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
            cb = mid * (1 + BACKOFF) ** 2
            if all(_pd_proved(X, 0.0)[0] for X in cand) and all(
                    lmi_proved(cb, cand[i], E, cand[(i + 1) % N])[0] for i in range(N) for E in Es[i]):
                hi = mid
                best = cand
                continue
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
