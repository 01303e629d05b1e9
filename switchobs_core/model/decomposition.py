"""Orthogonal observability decomposition (Lemma ``t:decomposition``) and the log norm.

For a pair (A, C) we compute an orthogonal T = [T_o T_u] with

    T' A T = [[A_o, 0], [A_uo, A_u]],   C T = [C_o, 0]        (e:A_obs_decomp, e:C_obs_decomp)

where T_u spans the unobservable subspace N(A, C) = ker O(A, C) and (A_o, C_o) is
observable.

Algorithm (no rank test of a stack of powers A^k): N is the largest A-invariant
subspace contained in ker C, the limit of the subspace iteration

    N_0 = ker C,   N_{k+1} = {x in N_k : A x in N_k},

which stops after at most n steps. Every step uses only orthonormal bases and an SVD:
with V_k an orthonormal basis of N_k and Q_k one of its orthogonal complement,
N_{k+1} = V_k ker(Q_k' A V_k). A singular value counts as zero when it is at most
``rtol`` times the scale of the matrix it belongs to (``rtol * ||C||_2`` for ker C,
``rtol * max(||A||_2, tiny)`` for the invariance steps); the default ``rtol = 1e-9``
is documented in :data:`DEFAULT_RTOL`. Badly scaled systems are handled as well as
any orthogonal method can: the decision is relative to ||A|| and ||C||, so state
scaling that makes modes differ by more than 1/rtol in magnitude will hide them.

Canonical basis. The subspaces are unique but their orthonormal bases are not; gains
and trajectories depend on the basis (any orthonormal basis of the observable subspace fits).
:func:`canonical_basis` fixes one by
a stated rule: the eigenvectors of the compression V' W V of the fixed weighting
W = diag(1, 2, ..., n), sorted by eigenvalue, each signed so that its entry of largest
magnitude is positive. Any two orthonormal bases V and V R of one subspace give the
same result (when the compression's eigenvalues are distinct, which holds
generically), so the basis depends on the subspace only. For coordinate-aligned
subspaces (the paper's model) the result is the coordinate axes themselves.

States the output never reaches (no chain of nonzero entries of A leads from them to
a state C reads) are unobservable coordinate axes, exactly; where there are such
states the iteration runs on the reached ones only (:func:`_reduced`, the same
subspaces and rule at the cost of the reached states), except where two of the
rule's eigenvalues are within :data:`TIE` ``* n`` (identical bodies read alike): the
rule's basis then depends on the eigenvalue solver's split of the eigenspace, and the
whole-state iteration, the reference, runs.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..exceptions import InvalidArgument
from ..validation import as_matrix

__all__ = [
    "DEFAULT_RTOL",
    "Decomposition",
    "observability_decomposition",
    "unobservable_subspace",
    "canonical_basis",
    "log_norm",
    "spectral_abscissa",
]

#: Relative tolerance under which a singular value counts as zero (see module docstring).
DEFAULT_RTOL = 1e-9

#: Two eigenvalues of the canonical rule's compression closer than ``TIE * n`` count as equal: there the
#: basis the rule picks depends on how the eigenvalue solver splits the eigenspace, so the decomposition
#: restricted to the reached states (:func:`_reduced`) gives way to the whole-state iteration, whose
#: basis is the one tables designed on any path store.
TIE = 1e-6


@dataclass(frozen=True)
class Decomposition:
    """The orthogonal observability decomposition of one channel (Lemma ``t:decomposition``).

    Attributes
    ----------
    T : (n, n) ndarray
        Orthogonal, ``T = [T_o T_u]`` (e:T_orthogonal).
    r : int
        Observable dimension r_i = rank O(A, C_i).
    A_o, C_o : ndarray
        Observable blocks of ``T' A T`` and ``C T`` (e:block_structure).
    A_uo, A_u : ndarray
        Lower blocks of ``T' A T``.
    residual : float
        Largest of ||T_o' A T_u|| and ||C T_u|| (both zero in exact arithmetic),
        relative to max(||A||, ||C||, 1).
    """

    T: np.ndarray
    r: int
    A_o: np.ndarray
    C_o: np.ndarray
    A_uo: np.ndarray
    A_u: np.ndarray
    residual: float

    @property
    def T_o(self) -> np.ndarray:
        """Orthonormal basis of the observable subspace (n x r)."""
        return self.T[:, : self.r]

    @property
    def T_u(self) -> np.ndarray:
        """Orthonormal basis of the unobservable subspace (n x (n - r))."""
        return self.T[:, self.r :]

    @property
    def observable(self) -> bool:
        """Whether (A, C) itself is observable (r = n)."""
        return self.r == self.T.shape[0]

    @property
    def unobservable_eigenvalues(self) -> np.ndarray:
        """Eigenvalues of A_u: the modes this channel cannot see."""
        if self.A_u.size == 0:
            return np.zeros(0, dtype=complex)
        return np.linalg.eigvals(self.A_u)

    @property
    def detectable(self) -> bool:
        """Whether every unobservable mode is asymptotically stable (Re < 0)."""
        ev = self.unobservable_eigenvalues
        return bool(np.all(ev.real < 0))

    @property
    def mu(self) -> float:
        """Log norm mu_i = lambda_max(sym(A_o)) (e:mu_o_i_def)."""
        return log_norm(self.A_o)


def _null_space(M: np.ndarray, thresh: float) -> np.ndarray:
    """Orthonormal basis of {x : M x = 0}, singular values <= thresh counting as zero."""
    n = M.shape[1]
    if M.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(M, full_matrices=True)
    rank = int(np.sum(s > thresh))
    return vt[rank:].T.copy()


def _complement(V: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the orthogonal complement of range(V) (V orthonormal)."""
    n, k = V.shape
    if k == 0:
        return np.eye(n)
    q, _ = np.linalg.qr(V, mode="complete")
    return q[:, k:]


def unobservable_subspace(A: ArrayLike, C: ArrayLike, *, rtol: float = DEFAULT_RTOL) -> np.ndarray:
    """Orthonormal basis of the unobservable subspace ker O(A, C) (n x (n - r)).

    Computed by the orthogonal subspace iteration of the module docstring.
    """
    A = as_matrix(A, "A", square=True)
    C = as_matrix(C, "C", cols=A.shape[0])
    return _unobservable(A, C, _check_rtol(rtol), float(np.linalg.norm(A, 2)))


def _unobservable(A: np.ndarray, C: np.ndarray, rtol: float, norm_a: float) -> np.ndarray:
    """:func:`unobservable_subspace` of checked ``A``, ``C``, ``rtol``, given ``norm_a = ||A||_2``."""
    scale_a = max(norm_a, np.finfo(float).tiny)
    scale_c = np.linalg.norm(C, 2) if C.size else 0.0
    V = _null_space(C, rtol * scale_c)
    for _ in range(A.shape[0] + 1):
        k = V.shape[1]
        if k == 0:
            break
        Q = _complement(V)
        if Q.shape[1] == 0:
            break
        Z = _null_space(Q.T @ A @ V, rtol * scale_a)
        if Z.shape[1] == k:
            break
        V, _ = np.linalg.qr(V @ Z)
        V = V[:, : Z.shape[1]]
    return V


def canonical_basis(V: np.ndarray) -> np.ndarray:
    """Canonical orthonormal basis of range(V) (rule in the module docstring)."""
    V = as_matrix(V, "V")
    n, k = V.shape
    if k == 0:
        return np.zeros((n, 0))
    return _canonical(V, np.arange(1.0, n + 1.0))[0]


def _canonical(V: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`canonical_basis` of ``V`` (k >= 1 columns) with the weights ``W`` (one per row), and the
    compression's eigenvalues (ascending, one per column)."""
    k = V.shape[1]
    M = V.T @ (W[:, None] * V)
    ev, R = np.linalg.eigh((M + M.T) / 2)
    B = V @ R
    # each column signed so that its first entry within 1e-8 of its largest magnitude is positive
    mag = np.abs(B)
    idx = np.argmax(mag > (1 - 1e-8) * mag.max(axis=0), axis=0)
    B[:, B[idx, np.arange(k)] < 0] *= -1.0
    # Re-orthonormalise against rounding without changing the span or the signs.
    q, r = np.linalg.qr(B)
    return q * np.sign(np.diag(r)), ev


def _reached(nz: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The states the output can ever depend on (sorted indices), ``nz`` the pattern ``A != 0``: those
    ``C`` reads, and every state an entry of ``A`` couples into a state already reached. The others span
    an ``A``-invariant coordinate subspace inside ker C (``A[R, out] = 0``, ``C[:, out] = 0``):
    unobservable, exactly."""
    reach = (C != 0).any(axis=0)
    while True:
        grown = reach | nz[reach].any(axis=0)
        if (grown == reach).all():
            return np.flatnonzero(reach)
        reach = grown


def _whole(A: np.ndarray, C: np.ndarray, rtol: float, norm_a: float) -> tuple[np.ndarray, int]:
    """``(T, r)`` by the subspace iteration on every state (module docstring)."""
    n = A.shape[0]
    Vu = canonical_basis(_unobservable(A, C, rtol, norm_a))
    To = canonical_basis(_complement(Vu)) if Vu.shape[1] else canonical_basis(np.eye(n))
    return np.hstack([To, Vu]), To.shape[1]


def _reduced(A: np.ndarray, C: np.ndarray, R: np.ndarray, rtol: float,
             norm_a: float) -> tuple[np.ndarray, int, np.ndarray, np.ndarray] | None:
    """``(T, r)`` when the output reaches only the states ``R`` (a system of decoupled bodies), with
    the unreached states ``out`` and the column of ``T`` that is each one's axis; None where two
    eigenvalues of the rule's compression are within :data:`TIE` ``* n`` (identical bodies read
    alike): the caller takes the whole-state iteration there.

    The subspace iteration runs on the reached states alone, with the same thresholds (``rtol``
    times the full ``||A||_2`` and ``||C||_2``): the unobservable subspace is its result plus the
    coordinate axes of the states never reached, and the canonical rule, whose weighting is diagonal,
    takes the two parts apart: the axes are their own canonical vectors (the weight of their
    coordinate as eigenvalue), merged by eigenvalue with the reduced part's (weighted by its
    coordinates' weights). The same subspaces and rule as on the whole state, at the cost of the
    reached states (8 of 132 for one agent of ``camera_agents`` with 32 agents)."""
    n = A.shape[0]
    W = np.arange(1.0, n + 1.0)
    unreached = np.ones(n, dtype=bool)
    unreached[R] = False
    out = np.flatnonzero(unreached)      # (not np.setdiff1d: its np.unique imports numpy.ma)
    VR = _unobservable(A[np.ix_(R, R)], C[:, R], rtol, norm_a)
    BoR, evo = _canonical(_complement(VR), W[R])
    r = BoR.shape[1]
    if VR.shape[1]:
        BR, evR = _canonical(VR, W[R])
    else:
        BR, evR = np.zeros((R.size, 0)), np.zeros(0)
    evu = np.concatenate([W[out], evR])
    if _tied(evo, n) or _tied(evu, n):
        return None
    order = np.argsort(evu, kind="stable")
    place = np.empty_like(order)
    place[order] = np.arange(order.size) + r      # the column of T of each unobservable vector
    at = place[: out.size]
    T = np.zeros((n, n))
    T[R, :r] = BoR
    T[out, at] = 1.0
    T[np.ix_(R, place[out.size:])] = BR
    return T, r, out, at


def _tied(ev: np.ndarray, n: int) -> bool:
    """Whether two of the eigenvalues ``ev`` are within :data:`TIE` ``* n`` of each other."""
    return ev.size > 1 and bool(np.diff(np.sort(ev)).min() < TIE * n)


def _transformed(A: np.ndarray, C: np.ndarray, T: np.ndarray, R: np.ndarray, out: np.ndarray,
                 at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(T' A T, C T)`` for a ``T`` of :func:`_reduced`: its rows outside ``R`` are the unit rows of the
    unreached states ``out`` (a 1 in column ``at``), ``C`` reads only ``R`` and ``A[R, out] = 0``.

    With the columns of ``T`` reordered as ``[inner, at]`` (``inner``: those nonzero on ``R``),
    ``T' A T`` is ``[[T_RI' A_RR T_RI, 0], [A[out, R] T_RI, A[out, out]]]``, reordered back: the products
    over ``R`` only; for a ``T`` of signed unit entries the doubles of the full products."""
    n = A.shape[0]
    inner = np.ones(n, dtype=bool)
    inner[at] = False
    inner = np.flatnonzero(inner)           # the columns of T nonzero on R
    TR = T[R][:, inner]
    AR = A[:, R]
    m = inner.size
    At = np.zeros((n, n))
    At[:m, :m] = TR.T @ (AR[R] @ TR)
    At[m:, :m] = AR[out] @ TR
    At[m:, m:] = A[out][:, out]
    back = np.empty(n, dtype=np.intp)
    back[np.concatenate([inner, at])] = np.arange(n)
    Ct = np.zeros((C.shape[0], n))
    Ct[:, :m] = C[:, R] @ TR
    return At.take(back, axis=0).take(back, axis=1), Ct.take(back, axis=1)


def observability_decomposition(A: ArrayLike, C: ArrayLike, *, rtol: float = DEFAULT_RTOL,
                                norm_a: float | None = None) -> Decomposition:
    """Orthogonal observability decomposition of (A, C) (Lemma ``t:decomposition``).

    ``D = observability_decomposition(A, C)``

    Parameters
    ----------
    A : (n, n) array_like
    C : (p, n) array_like
    rtol : float
        Relative rank tolerance (see module docstring).
    norm_a : float, optional
        ``||A||_2`` (``np.linalg.norm(A, 2)``) when the caller has it already (a system decomposes
        every channel with the same ``A``): the same result, one SVD of ``A`` fewer per call.

    Returns
    -------
    Decomposition
        With canonical, deterministic bases T_o and T_u.

    Raises
    ------
    InvalidArgument
        Wrong shapes or non-finite entries.
    """
    A = as_matrix(A, "A", square=True)
    C = as_matrix(C, "C", cols=A.shape[0])
    rtol = _check_rtol(rtol)
    norm_a = float(np.linalg.norm(A, 2)) if norm_a is None else float(norm_a)
    return _decompose(A, C, rtol, norm_a, A != 0)


def _decompose(A: np.ndarray, C: np.ndarray, rtol: float, norm_a: float, nz: np.ndarray) -> Decomposition:
    """:func:`observability_decomposition` of checked ``A``, ``C``, ``rtol``, given ``norm_a = ||A||_2``
    and ``nz = A != 0`` (a system decomposes every channel with the same ``A``)."""
    n = A.shape[0]
    R = _reached(nz, C)
    reduced = None if R.size in (0, n) else _reduced(A, C, R, rtol, norm_a)
    if reduced is None:
        T, r = _whole(A, C, rtol, norm_a)
        At = T.T @ A @ T
        Ct = C @ T
    else:
        T, r, out, at = reduced
        At, Ct = _transformed(A, C, T, R, out, at)
    scale = max(norm_a, np.linalg.norm(C, 2) if C.size else 0.0, 1.0)
    res = 0.0
    if r < n:
        res = max(np.linalg.norm(At[:r, r:], 2), np.linalg.norm(Ct[:, r:], 2) if C.size else 0.0)
    return Decomposition(
        T=T,
        r=r,
        A_o=At[:r, :r].copy(),
        C_o=Ct[:, :r].copy(),
        A_uo=At[r:, :r].copy(),
        A_u=At[r:, r:].copy(),
        residual=float(res / scale),
    )


def log_norm(M: ArrayLike) -> float:
    """Logarithmic 2-norm mu(M) = lambda_max((M + M') / 2) (e:mu2_formula)."""
    M = _square_or_empty(M)
    if M.size == 0:
        return float("-inf")
    return float(np.linalg.eigvalsh((M + M.T) / 2)[-1])


def spectral_abscissa(M: ArrayLike) -> float:
    """alpha(M) = max Re lambda(M) (Lemma ``t:uniform-euclidean-bound``)."""
    M = _square_or_empty(M)
    if M.size == 0:
        return float("-inf")
    return float(np.max(np.linalg.eigvals(M).real))


def _square_or_empty(M: ArrayLike) -> np.ndarray:
    """``M`` as a finite square matrix (an empty one allowed: r_i = 0), or InvalidArgument naming M."""
    arr = np.asarray(M, dtype=float) if not isinstance(M, np.ndarray) else M.astype(float, copy=False)
    if arr.size == 0:
        return arr.reshape(0, 0)
    return as_matrix(arr, "M", square=True)


def _check_rtol(rtol: float) -> float:
    try:
        val = float(rtol)
    except (TypeError, ValueError):
        raise InvalidArgument(f"rtol must be a number; got {rtol!r}") from None
    if not (math.isfinite(val) and 0 <= val < 1):
        raise InvalidArgument(f"rtol must be a finite relative tolerance in [0, 1); got {val}")
    return val
