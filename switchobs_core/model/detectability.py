"""Detectability of a sampled periodic pair, scale-free for large n (beyond the paper).

Samples at ``t_k = k dt``, k = 0..K-1, of ``xdot = A x`` (e:system) with the rows ``H_k`` measured at
sample k, repeated with period ``T = K dt``: the pair (``Phi = e^{A dt}``, ``H_k``) is detectable
when every mode of the monodromy ``Phi^K`` with ``|mu| >= 1`` is seen by some sample
(d:obs_detect, e:detectability_condition in discrete time). By the PBH test for periodic pairs
(Bittanti and Colaneri, *Periodic Systems*, Springer 2009, Sec. 4.1) it is enough to test the
eigenvectors of the monodromy. ``Phi^K`` has the eigenvectors of ``A``, combined across
eigenvalues ``lambda_i`` of A that the period aliases (``e^{lambda_i T}`` equal); for such a group
a vector ``v = sum_i V_i c_i`` (``V_i`` a basis of the eigenvectors of ``lambda_i``) gives
``H_k Phi^k v = e^{Re(lambda) t_k} sum_i e^{j Im(lambda_i) t_k} H_k V_i c_i``, so ``v`` is never
seen exactly when ``c`` lies in the null space of the stacked rows

.. math::

    \\left[ e^{j \\omega_1 t_k} H_k V_1, \\; \\dots, \\; e^{j \\omega_m t_k} H_k V_m \\right]_{k = 0..K-1},
    \\quad \\omega_i = \\operatorname{Im} \\lambda_i .

The common growth ``e^{Re(lambda) t_k}`` is factored out: nothing in the test grows with the
period (the stacked observability matrix ``[H_0; H_1 Phi; ...]`` and ``Phi^K`` of a 32-agent
camera model span e^32 and made the integrators look unobservable). Tolerances, each relative:

* a mode counts as *not stable* when ``Re(lambda) >= -MARGINAL_RTOL max(1, ||A||)`` (integrators,
  whose computed eigenvalues are ~1e-8 off zero in a Jordan block, included);
* eigenvalues within ``CLUSTER_RTOL max(1, ||A||)`` are one eigenvalue (a Jordan block splits
  by ~sqrt(eps));
* the computed eigenvectors of one cluster span as many directions as their singular values
  above ``EIGVEC_RTOL`` times the largest (a Jordan block's are nearly parallel);
* a singular value of the stacked rows at most ``NULL_RTOL`` times the largest is zero.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["MARGINAL_RTOL", "CLUSTER_RTOL", "EIGVEC_RTOL", "NULL_RTOL", "UndetectableMode", "undetectable_modes",
           "aliasing_free"]

MARGINAL_RTOL = 1e-7
CLUSTER_RTOL = 1e-5
EIGVEC_RTOL = 1e-4
NULL_RTOL = 1e-9


@dataclass(frozen=True)
class UndetectableMode:
    """A mode never seen: eigenvalue ``lam`` of A (continuous time, ``Re >= 0`` up to the tolerance)
    and a real unit direction ``v`` in state space."""

    lam: complex
    v: np.ndarray


@lru_cache(maxsize=8)
def _eigen_groups(A_bytes: bytes, n: int, T: float) -> tuple:
    """The not-stable eigenvalues of A, grouped when the period T aliases them: a tuple of groups,
    each a tuple of ``(lambda, V)`` with V an orthonormal basis of lambda's eigenvectors."""
    A = np.frombuffer(A_bytes, dtype=float).reshape(n, n)
    scale = max(1.0, float(np.linalg.norm(A, 2)))
    lam, X = np.linalg.eig(A)
    keep = lam.real >= -MARGINAL_RTOL * scale
    lam, X = lam[keep], X[:, keep]
    # 1. clusters of (numerically) one eigenvalue
    clusters: list[list[int]] = []
    for i in sorted(range(lam.size), key=lambda i: (round(lam[i].real, 6), round(lam[i].imag, 6))):
        for c in clusters:
            if abs(lam[i] - lam[c[0]]) <= CLUSTER_RTOL * scale:
                c.append(i)
                break
        else:
            clusters.append([i])
    # 2. an orthonormal basis of each cluster's eigenvectors (a Jordan block's computed
    #    eigenvectors are nearly parallel: one direction)
    eig: list[tuple[complex, np.ndarray]] = []
    for c in clusters:
        lb = complex(np.mean(lam[c]))
        Xc = X[:, c]
        if abs(lb.imag) <= CLUSTER_RTOL * scale:     # a real eigenvalue: real eigenvectors
            lb, Xc = complex(lb.real), np.hstack([Xc.real, Xc.imag])
        U, s, _ = np.linalg.svd(Xc, full_matrices=False)
        eig.append((lb, U[:, s > EIGVEC_RTOL * s[0]].astype(complex)))
    # 3. groups aliased by the period: equal e^{lambda T}
    groups: list[list[tuple[complex, np.ndarray]]] = []
    for lb, V in eig:
        mu = np.exp(lb * T)
        for g in groups:
            mg = np.exp(g[0][0] * T)
            if abs(mu - mg) <= CLUSTER_RTOL * max(abs(mu), abs(mg)):
                g.append((lb, V))
                break
        else:
            groups.append([(lb, V)])
    return tuple(tuple(g) for g in groups)


def aliasing_free(A: np.ndarray, T: float) -> bool:
    """Whether no two not-stable eigenvalues of A alias over the period ``T`` (every group one
    eigenvalue): then detectability depends only on which row sets are measured, not when."""
    A = np.ascontiguousarray(A, dtype=float)
    return all(len(g) == 1 for g in _eigen_groups(A.tobytes(), A.shape[0], float(T)))


def undetectable_modes(A: np.ndarray, H: Sequence[np.ndarray], dt: float) -> list[UndetectableMode]:
    """The not-stable modes of A that no sample of the periodic pattern sees (module docstring).

    ``H[k]`` are the rows measured at sample k = 0..K-1 (``t_k = k dt``); an empty list means
    the sampled periodic pair is detectable.
    """
    A = np.ascontiguousarray(A, dtype=float)
    n, K = A.shape[0], len(H)
    T = K * dt
    # distinct row sets and the sample times at which each is measured
    rows: dict[bytes, tuple[np.ndarray, list[float]]] = {}
    for k, Hk in enumerate(H):
        Hk = np.asarray(Hk, dtype=float).reshape(-1, n)
        e = rows.setdefault(Hk.tobytes() + bytes(str(Hk.shape), "ascii"), (Hk, []))
        e[1].append(k * dt)
    out: list[UndetectableMode] = []
    for group in _eigen_groups(A.tobytes(), n, float(T)):
        blocks = []
        for Hk, ts in rows.values():
            if Hk.shape[0] == 0:
                continue
            if len(group) == 1:
                # one eigenvalue: the phase e^{j w t_k} multiplies whole rows and drops out
                blocks.append(Hk @ group[0][1])
                continue
            # rows e^{j w_i t_k} H V_i at every sample t_k of this row set
            t = np.asarray(ts)
            parts = [np.exp(1j * lb.imag * t)[:, None, None] * (Hk @ V)[None] for lb, V in group]
            blocks.append(np.concatenate(parts, axis=2).reshape(-1, sum(V.shape[1] for _, V in group)))
        d = sum(V.shape[1] for _, V in group)
        Mx = np.vstack(blocks) if blocks else np.zeros((0, d))
        if Mx.shape[0]:
            _, s, Vh = np.linalg.svd(Mx)
            smax = s[0] if s.size else 0.0
            s_full = np.concatenate([s, np.zeros(d - s.size)])
            null = Vh[s_full <= NULL_RTOL * max(smax, np.finfo(float).tiny)]
        else:
            null = np.eye(d)
        Vcat = np.hstack([V for _, V in group])
        for c in null:
            v = Vcat @ c.conj()
            v = v.real if np.linalg.norm(v.real) >= np.linalg.norm(v.imag) else v.imag
            out.append(UndetectableMode(group[0][0], v / np.linalg.norm(v)))
    return out
