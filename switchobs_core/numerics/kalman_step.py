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
"""

from __future__ import annotations

import numpy as np

from ..exceptions import RiccatiError

__all__ = ["symmetrize", "predict_cov", "gain", "joseph", "correct_state", "riccati_step"]


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
