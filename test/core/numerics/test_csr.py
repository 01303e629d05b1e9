"""Sparse products through scipy's kernels (switchobs_core.numerics.csr): the public product's
doubles, bit for bit (the same kernel, the same sums; one process)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_array

from switchobs_core.numerics.csr import csr_matmat, csr_matvec


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 30), n=st.integers(1, 30), r=st.integers(1, 6), fill=st.floats(0.0, 1.0),
       seed=st.integers(0, 2**32 - 1), transposed=st.booleans())
def test_products_equal_the_public_ones(m, n, r, fill, seed, transposed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((m, n)) * (rng.random((m, n)) < fill) * 10.0 ** rng.integers(-8, 8, (m, n))
    S = csr_array(A)
    x = rng.standard_normal(n)
    B = rng.standard_normal((r, n)).T if transposed else rng.standard_normal((n, r))   # not C-contiguous, or it is
    args = (S.indptr, S.indices, S.data, S.shape)
    assert np.array_equal(csr_matvec(*args, x), S @ x)
    assert np.array_equal(csr_matmat(*args, B), S @ B)
    np.testing.assert_allclose(csr_matmat(*args, B), A @ B, rtol=1e-12, atol=1e-12 * np.abs(A).max(initial=0) *
                               np.abs(B).max())
