"""switchobs_core.numerics.norms: the gains' spectral norms and the estimation error's norm."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.numerics.norms import error_norm, gain_norms


def test_gain_norms_are_the_largest_singular_values():
    L = [np.array([[3.0, 0.0], [0.0, -4.0]]), np.array([[1.0], [1.0], [1.0]])]
    assert gain_norms(L) == pytest.approx([4.0, np.sqrt(3.0)], rel=1e-15)
    assert all(isinstance(v, float) for v in gain_norms(L))


def test_error_norm_is_euclidean():
    assert error_norm(np.array([1.0, 2.0, 2.0]), np.zeros(3)) == 3.0
    assert error_norm(np.array([4.0, 1.0]), np.array([1.0, -3.0])) == 5.0
