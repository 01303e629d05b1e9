"""The rows' covariance ``C_r S C_r'`` over the columns the rows see (the innovation test's
projected bound, the bias test's innovation variance): the same doubles as the dense product
for rows that each select one state (a camera's and a target's positions), equal to rounding for
rows that mix states, the dense product where the rows see more than a quarter of the states."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.runtime.consistency import innovation_allowance, projected_bound, rows_product, seen_columns


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    X = rng.standard_normal((n, n))
    S = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    return 0.5 * (S + S.T)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(16, 140), p=st.integers(1, 4), scale=st.floats(1e-10, 1e10))
def test_selector_rows_give_the_dense_product_exactly(seed, n, p, scale):
    rng = np.random.default_rng(seed)
    C = np.zeros((p, n))
    C[np.arange(p), rng.choice(n, size=p, replace=False)] = 1.0
    S = _spd(rng, n, scale)
    cols = seen_columns(C)
    assert cols is not None and cols.size == p
    np.testing.assert_array_equal(rows_product(C, S, cols), C @ S @ C.T)
    assert projected_bound(C, S, cols) == projected_bound(C, S)
    x, y = rng.standard_normal(n), rng.standard_normal(p)
    assert innovation_allowance(C, S, 0.1, x, y, cols=cols) == innovation_allowance(C, S, 0.1, x, y)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(16, 140), p=st.integers(1, 4), k=st.integers(1, 3))
def test_mixing_rows_give_the_dense_product_to_rounding(seed, n, p, k):
    rng = np.random.default_rng(seed)
    C = np.zeros((p, n))
    seen = rng.choice(n, size=min(n // 4, k * p), replace=False)
    C[:, seen] = rng.standard_normal((p, seen.size))
    S = _spd(rng, n, 1.0)
    cols = seen_columns(C)
    assert cols is not None and set(cols.tolist()) <= set(seen.tolist())
    dense = C @ S @ C.T
    np.testing.assert_allclose(rows_product(C, S, cols), dense, rtol=0, atol=1e-13 * np.abs(C).sum() ** 2 *
                               np.abs(S).max())


def test_rows_that_see_many_states_take_the_dense_product():
    rng = np.random.default_rng(0)
    C = rng.standard_normal((2, 40))
    assert seen_columns(C) is None
    C[:, 11:] = 0.0                      # 11 of 40 seen: more than a quarter
    assert seen_columns(C) is None
    C[:, 10] = 0.0                       # 10 of 40: the subset
    assert seen_columns(C).tolist() == list(range(10))
