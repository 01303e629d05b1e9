"""The exact error map over one cycle and its certificate (from e:xtilde_dyn_piecewise).

``Phi = expm((A - L_N C_N) h_N) ... expm((A - L_1 C_1) h_1)``; a periodic schedule converges
iff its spectral radius is < 1, and ``||x_tilde(t_{k+1})|| <= ||Phi|| ||x_tilde(t_k)||``.

Equation labels (``e:...``) are those of the paper and resolve in ``docs/equations.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..exceptions import InvalidArgument
from ..validation import as_matrix
from .paper import check_residences, design_dead_time, paper_factors

__all__ = ["cycle_transition", "CycleCertificate", "certify_cycle"]


def cycle_transition(A: Any, C: Sequence[Any], L: Sequence[Any], h: Sequence[float],
                     dead_time: float = 0.0) -> np.ndarray:
    """Exact error transition over one cycle (e:xtilde_dyn_piecewise).

    ``Phi = expm((A - L_N C_N) h_N) @ ... @ expm((A - L_1 C_1) h_1)``; with a dead time ``d``
    every residence starts blind, where the LMI observer applies no gain:
    ``expm((A - L_i C_i) (h_i - d)) expm(A d)`` (:mod:`switchobs_core.model.schedule`).

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
    h = check_residences(h, len(C))
    C = [as_matrix(Ci, f"C_{i + 1}", cols=n) for i, Ci in enumerate(C)]
    L = [as_matrix(Li, f"L_{i + 1}", rows=n, cols=Ci.shape[0]) for i, (Li, Ci) in enumerate(zip(L, C))]
    d = float(dead_time)
    if not (d >= 0 and d < min(h)):
        raise InvalidArgument(f"dead_time must be >= 0 and shorter than every residence; got {dead_time!r}")
    blind = expm(A * d) if d else None
    Phi = np.eye(n)
    for Ci, Li, hi in zip(C, L, h):
        if blind is not None:
            Phi = blind @ Phi
        Phi = expm((A - Li @ Ci) * (hi - d)) @ Phi
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
    h = check_residences(h, len(system.C))
    f = paper_factors(design, h)
    Phi = cycle_transition(system.A, system.C, design.L, h, design_dead_time(design))
    return CycleCertificate(h=h, f=f, paper_ok=max(f) < 1, Phi=Phi,
                            spectral_radius=float(np.max(np.abs(np.linalg.eigvals(Phi)))),
                            norm=float(np.linalg.norm(Phi, 2)))
