"""The k-sigma ellipse of a 2 x 2 position covariance (what RViz draws for a body's uncertainty).

``P_pp = V diag(l) V'`` with ascending eigenvalues ``l``: the ellipse ``{p : p' P_pp^-1 p <= k^2}``
has semi-axes ``k sqrt(l_i)`` along the columns of ``V``; the major axis lies along ``V[:, 1]``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["covariance_ellipse", "covariance_ellipses"]


def covariance_ellipse(P_pp: np.ndarray, sigmas: float = 2.0) -> tuple[float, float, float] | None:
    """``(major, minor, yaw)`` of the ``sigmas``-sigma ellipse of the 2 x 2 covariance ``P_pp``: the
    full axis lengths ``2 sigmas sqrt(l)`` and the major axis' angle (rad) from the x axis; None when
    ``P_pp`` is not finite. The symmetric part is used, and negative eigenvalues (rounding) count as 0.
    """
    P = np.asarray(P_pp, dtype=float)
    if P.shape != (2, 2) or not np.isfinite(P).all():
        return None
    l, V = np.linalg.eigh(0.5 * (P + P.T))
    l = np.clip(l, 0.0, None)
    return (2.0 * sigmas * math.sqrt(l[1]), 2.0 * sigmas * math.sqrt(l[0]), math.atan2(V[1, 1], V[0, 1]))


def covariance_ellipses(P_pp: np.ndarray, sigmas: float = 2.0) -> list[tuple[float, float, float] | None]:
    """:func:`covariance_ellipse` of each 2 x 2 block of a ``(k, 2, 2)`` stack, the same doubles, with
    one eigen-decomposition call for the finite ones (numpy's ``eigh`` runs the same LAPACK routine
    on each matrix of a stack; the square roots are correctly rounded in both, the angles taken
    with :mod:`math` as there); None for a block that is not finite."""
    P = np.asarray(P_pp, dtype=float)
    out: list[tuple[float, float, float] | None] = [None] * P.shape[0]
    ok = np.isfinite(P).all(axis=(1, 2))
    if not ok.all():
        ok = np.flatnonzero(ok)
        if not ok.size:
            return out
        P = P[ok]
    else:
        ok = range(P.shape[0])
    lam, V = np.linalg.eigh(0.5 * (P + P.transpose(0, 2, 1)))
    lam = np.clip(lam, 0.0, None)
    major, minor = (2.0 * sigmas * np.sqrt(lam[:, 1])).tolist(), (2.0 * sigmas * np.sqrt(lam[:, 0])).tolist()
    for k, a, b, vy, vx in zip(ok, major, minor, V[:, 1, 1].tolist(), V[:, 0, 1].tolist()):
        out[k] = (a, b, math.atan2(vy, vx))
    return out
