"""The 2-sigma ellipses of a stack of 2 x 2 covariances in one call: each block's the same doubles
as ``covariance_ellipse`` alone (full rank, rank one, zero, rotated beyond 90 degrees, asymmetric
rounding, a non-finite block: None for that block only)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.ellipse import covariance_ellipse, covariance_ellipses


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), k=st.integers(1, 40), scale=st.floats(1e-12, 1e12),
       bad=st.lists(st.sampled_from([math.nan, math.inf, -math.inf]), max_size=3),
       sigmas=st.sampled_from([1.0, 2.0, 3.0]))
def test_each_block_is_covariance_ellipse_of_it(seed, k, scale, bad, sigmas):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((k, 2, 2))
    P = scale * A @ A.transpose(0, 2, 1)
    P[rng.random(k) < 0.2, 1, :] = 0.0                       # rank one or zero blocks
    P += 1e-17 * scale * rng.standard_normal((k, 2, 2))       # not exactly symmetric
    for v in bad:
        P[rng.integers(k), rng.integers(2), rng.integers(2)] = v
    got = covariance_ellipses(P, sigmas)
    assert got == [covariance_ellipse(P[i], sigmas) for i in range(k)]
    assert all((g is None) == (not np.isfinite(P[i]).all()) for i, g in enumerate(got))
