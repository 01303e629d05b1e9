"""The norms that the ROS layer reports: the gains' spectral norms (the estimator's diagnostics) and
the estimation error against a recorded truth (the bag report).

The estimation error is ``x_tilde = x_hat - x`` (e:est_error); the published bounds bound its
Euclidean norm.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["error_norm", "gain_norms"]


def gain_norms(L: Sequence[np.ndarray]) -> list[float]:
    """``||L_i||_2`` of each channel's gain ``L_i`` (e:L_original), in channel order."""
    return [float(np.linalg.norm(L_i, 2)) for L_i in L]


def error_norm(x_hat: np.ndarray, x: np.ndarray) -> float:
    """``||x_tilde|| = ||x_hat - x||`` (e:est_error), Euclidean."""
    return float(np.linalg.norm(x_hat - x))
