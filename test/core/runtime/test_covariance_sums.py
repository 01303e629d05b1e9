"""``covariance._added``: the prior's sums taken in the product's own array give the doubles, and the
memory order, of the sums taken in new arrays (``symmetrize((X + Q_d) + H)``)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.kalman_step import symmetrize
from switchobs_core.runtime.covariance import _added


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 12), seed=st.integers(0, 2 ** 32 - 1), order=st.sampled_from(["C", "F", "T"]),
       held=st.booleans(), scale=st.floats(1e-8, 1e8))
def test_sums_in_place_are_the_new_arrays_sums(n, seed, order, held, scale):
    """Property: any product ``X`` (C order, Fortran order, a transposed view as the sparse sandwich
    returns), ``Q_d``, held noise or none: the same doubles bit for bit and the same memory order."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, n)) * scale
    X = np.asfortranarray(X) if order == "F" else (np.ascontiguousarray(X.T).T if order == "T" else X)
    Q = rng.standard_normal((n, n))
    H = rng.standard_normal((n, n)) * 1e-3 if held else None
    want = symmetrize(X + Q + H if held else X + Q)
    got = _added(X.copy(order="K") if order != "T" else np.ascontiguousarray(X.T).T, Q, H)
    assert np.array_equal(got, want) and got.flags.c_contiguous == want.flags.c_contiguous
    assert np.array_equal(got, got.T)
