"""One Kalman filter step: the prediction, the gain and the Joseph-form correction (beyond the paper).

The one owner of the filter's step formulas: the periodic Riccati recursion and the offline
design (:mod:`switchobs_core.design.riccati`, :mod:`switchobs_core.design.doubling`,
:mod:`switchobs_core.design.kalman`), the stored Kalman gains' lookups
(:mod:`switchobs_core.table.kalman`) and the online filters (:mod:`switchobs_core.runtime`) call
these functions and nothing else. Between two samples the plant is discretised exactly
(:func:`~switchobs_core.design.riccati.discretize`: ``Phi = e^{A dt}``, ``Q_d``); one step is

* predict: ``x^- = Phi x^+ + Gamma B u``, ``P^- = Phi P^+ Phi' + Q_d``;
* correct with the rows ``H = C_rho[rows]`` of the active channel (e:outputs):
  ``S = H P^- H' + R``, ``K = P^- H' S^{-1}``, ``x^+ = x^- + K (y - H x^-)``,
  ``P^+ = (I - K H) P^- (I - K H)' + K R K'`` (Joseph form), then symmetrised.

The Joseph form stays symmetric PSD for any gain (also a gain from a stored, no longer exact
prior), and the plain ``P^+ = (I - K H) P^-`` lost symmetry and diverged after about 20
periods at 20 Hz in a check of ours. The noise-free error of one step is
``e^+_{k+1} = (I - K H) Phi e^+_k``, the sampled form of the error dynamics (e:error_dynamics).

Square-root form (:func:`sqrt_predict`, :func:`sqrt_correct`): the same step on a factor ``L``
with ``P = L L'``, by one QR of a pre-array per sample. ``P`` is then positive semidefinite by
construction, and ``L`` spans the square root of ``P``'s dynamic range: a covariance whose
eigenvalues span 1e20 (beyond the ~1e16 a double resolves, where ``S = H P H' + R`` of the
covariance form loses positive definiteness) is a factor spanning 1e10. The periodic design
(:mod:`switchobs_core.design.doubling`) and the online recursion
(:mod:`switchobs_core.runtime.families.online`) use it; :func:`check_factor` says when even the
factor has run out of digits (:class:`~switchobs_core.exceptions.CovarianceError`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dtrcon as _dtrcon

from ..exceptions import CovarianceError, RiccatiError

__all__ = ["symmetrize", "predict_cov", "gain", "joseph", "correct_state", "riccati_step", "psd_sqrt",
           "sqrt_correct", "sqrt_predict", "compress_factor", "check_factor", "FACTOR_RCOND"]

#: Smallest reciprocal condition number (1-norm, LAPACK's estimate) of a covariance factor, in units
#: of ``n`` unit roundoffs, that :func:`check_factor` accepts: below it ``L`` is singular to working
#: precision, and so is ``P = L L'`` (whose condition is the square of ``L``'s).
FACTOR_RCOND = 1.0
_U = 2.0 ** -53
#: LAPACK workspace of dgeqrf per shape: the size scipy.linalg.qr queries (the same blocking, the same doubles).
_LWORK: dict[tuple[int, int], int] = {}


def symmetrize(P: np.ndarray) -> np.ndarray:
    """``(P + P') / 2``."""
    return 0.5 * (P + P.T)


def predict_cov(P: np.ndarray, Phi: np.ndarray, Q_d: np.ndarray) -> np.ndarray:
    """``P^- = Phi P^+ Phi' + Q_d``, symmetrised."""
    # P^- = Phi P Phi' + Q_d
    return symmetrize(Phi @ P @ Phi.T + Q_d)


def gain(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Kalman gain ``K = P H' (H P H' + R)^{-1}`` (Cholesky solve of the innovation covariance).

    Raises
    ------
    RiccatiError
        ``S = H P H' + R`` is not positive definite.
    """
    if H.shape[0] == 0:          # no rows (a fully blind sample): no correction
        return np.zeros((P.shape[0], 0))
    PHt = P @ H.T
    # S = H P H' + R = L L' (Cholesky)
    S = symmetrize(H @ PHt + R)
    try:
        L = np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise RiccatiError(
            f"innovation covariance S = H P H' + R is not positive definite (min eigenvalue "
            f"{np.linalg.eigvalsh(S)[0]:.3g}); the measurement std must be > 0"
        ) from None
    # K = P H' S^-1: solve L Z = H P, then L' K' = Z (numpy's solvers: no wrapper cost per sample)
    return np.linalg.solve(L.T, np.linalg.solve(L, PHt.T)).T


def joseph(P: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Joseph form ``P^+ = (I - K H) P (I - K H)' + K R K'``, symmetrised (valid for any K).

    The two products with ``I - K H`` are taken as rank-p updates, ``X = (I - K H) P = P - K (H P)``
    and ``X (I - K H)' = X - (X H') K'``: the same formula, O(n^2 p) instead of two n x n products."""
    # X = (I - K H) P
    X = P - K @ (H @ P)
    # P^+ = X (I - K H)' + K R K'
    return symmetrize(X - (X @ H.T) @ K.T + K @ R @ K.T)


def correct_state(x: np.ndarray, K: np.ndarray, H: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``x^+ = x^- + K (y - H x^-)``."""
    return x + K @ (y - H @ x)


def riccati_step(P_prior: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Correction of the covariance at one sample: ``(K, P^+)`` from the prior ``P^-``."""
    K = gain(P_prior, H, R)
    return K, joseph(P_prior, K, H, R)


def _qr_r(a: np.ndarray) -> np.ndarray:
    """``R`` of ``a = Q R`` (rows ``min(m, n)``), the upper triangle of LAPACK's dgeqrf with the
    workspace scipy.linalg.qr queries: the doubles of ``qr(a, mode="r")``, without its checks and
    copies. ``a`` (Fortran order, float64) is overwritten."""
    m, n = a.shape
    lw = _LWORK.get((m, n))
    if lw is None:
        lw = _LWORK[(m, n)] = int(_dgeqrf(a, lwork=-1)[2][0])
    qr = _dgeqrf(a, lwork=lw, overwrite_a=1)[0]
    return np.triu(qr[:min(m, n)])


def psd_sqrt(P: np.ndarray) -> np.ndarray:
    """A square root ``L`` with ``L L' = P`` of a symmetric PSD matrix (eigenvalues < 0 from
    rounding clipped to 0); Cholesky when it succeeds."""
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(symmetrize(P))
        return V * np.sqrt(np.clip(w, 0.0, None))


def compress_factor(L: np.ndarray) -> np.ndarray:
    """An n x n lower-triangular factor with the product ``L L'`` of an n x m factor ``L`` (m > n;
    one QR of ``L'``); ``L`` itself when it is no wider than n."""
    n, m = L.shape
    if m <= n:
        return L
    return _qr_r(np.asfortranarray(L.T))[:n].T


def sqrt_correct(L: np.ndarray, H: np.ndarray, R_sqrt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Square-root Kalman correction: ``(K, L^+, S^{1/2})`` from a prior factor ``L`` (``P^- = L L'``,
    n x m with m >= n; ``L^+`` is n x n lower triangular).

    One QR of the pre-array (Kaminski, Bryson and Schmidt, IEEE TAC 16(6), 1971)

    .. math::

        \\begin{bmatrix} R^{1/2\\prime} & 0 \\\\ L' H' & L' \\end{bmatrix} = \\Theta
        \\begin{bmatrix} S^{1/2\\prime} & \\bar K' \\\\ 0 & L^{+\\prime} \\end{bmatrix},
        \\quad K = \\bar K S^{-1/2},

    so that ``S = H P^- H' + R``, ``K = P^- H' S^{-1}`` and ``P^+ = L^+ L^{+'}`` equals the Joseph
    form: positive semidefinite by construction, whatever the dynamic range of ``P^-``.
    ``S^{1/2}`` is lower triangular.
    """
    n, p = L.shape[0], H.shape[0]
    if p == 0:                               # nothing measured: only compress L to n x n
        return np.zeros((n, 0)), compress_factor(L), np.zeros((0, 0))
    pre = np.zeros((p + L.shape[1], p + n), order="F")
    pre[:p, :p] = R_sqrt.T
    pre[p:, :p] = (H @ L).T
    pre[p:, p:] = L.T
    post = _qr_r(pre)
    Ss = post[:p, :p].T                      # S^{1/2}
    Kbar = post[:p, p:].T                    # K S^{1/2}
    # K = Kbar S^{-1/2}: solve S^{1/2}' K' = Kbar'
    K = np.linalg.solve(Ss.T, Kbar.T).T
    return K, post[p:p + n, p:].T, Ss


def sqrt_predict(L: np.ndarray, Phi: np.ndarray, Qd_sqrt: np.ndarray) -> np.ndarray:
    """Square-root prediction: ``L^- = [Phi L, Q_d^{1/2}]`` (n x 2n), ``L^- L^-' = Phi L L' Phi' + Q_d``.

    Not triangular: the next :func:`sqrt_correct` compresses it in its QR (one QR per sample)."""
    return np.hstack([Phi @ L, Qd_sqrt])


def check_factor(L: np.ndarray, what: str) -> None:
    """Raise :class:`~switchobs_core.exceptions.CovarianceError` unless the lower-triangular factor
    ``L`` (``P = L L'``) is finite and nonsingular to working precision: LAPACK's estimate of its
    reciprocal condition number (1-norm) at least :data:`FACTOR_RCOND` ``n u`` (u = 2^-53), that
    is ``P``'s condition below about ``1 / (n u)^2`` (1e29 at n = 12). ``what`` names the step."""
    n = L.shape[0]
    if not np.all(np.isfinite(L)):
        raise CovarianceError(f"{what}: the covariance factor overflowed (an entry is not finite)")
    if n == 0:
        return
    rcond = float(_dtrcon(L, norm="1", uplo="L")[0])
    if not rcond >= FACTOR_RCOND * n * _U:
        d = np.abs(np.diagonal(L))
        raise CovarianceError(
            f"{what}: the covariance lost positive definiteness in double precision (its factor's reciprocal "
            f"condition {rcond:.2e}, below n u = {FACTOR_RCOND * n * _U:.2e}; its variances span "
            f"{d.min() ** 2:.3g} to {d.max() ** 2:.3g})")
