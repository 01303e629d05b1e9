"""``rounding.largest_eigenvalue``: ``np.linalg.eigvalsh(S)[-1]`` through its gufunc, the same
doubles, and the wrapper's behaviour where the solver gives no finite value (hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import largest_eigenvalue


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 12), scale=st.floats(1e-30, 1e30), fortran=st.booleans())
def test_the_same_doubles_as_eigvalsh(seed, n, scale, fortran):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, n)) * scale
    S = 0.5 * (X + X.T)
    if fortran:
        S = np.asfortranarray(S)
    assert largest_eigenvalue(S) == float(np.linalg.eigvalsh(S)[-1])


def test_not_finite_as_the_wrapper():
    S = np.eye(3)
    S[0, 1] = S[1, 0] = np.nan
    try:
        want = float(np.linalg.eigvalsh(S)[-1])
    except np.linalg.LinAlgError:
        with pytest.raises(np.linalg.LinAlgError):
            largest_eigenvalue(S)
    else:
        got = largest_eigenvalue(S)
        assert got == want or (got != got and want != want)
