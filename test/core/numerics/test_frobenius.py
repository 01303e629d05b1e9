"""fro_upper: a computed Frobenius norm plus what underflow hides is an upper bound on the exact norm
(up to the relative rounding the callers allow for), at scales where the squares underflow too."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.frobenius import fro_upper, underflow_slack
from switchobs_core.numerics.rounding import fro_norm, gamma


def _exact_sq(x: np.ndarray) -> Fraction:
    """``||x||_F^2`` exactly (every double is a dyadic rational)."""
    return sum((Fraction(float(v)) ** 2 for v in x.ravel()), Fraction(0))


@settings(max_examples=150, deadline=None)
@given(m=st.integers(1, 40), exp=st.integers(-170, 3), seed=st.integers(0, 2**31 - 1),
       shape2=st.booleans())
def test_fro_upper_bounds_the_exact_norm(m: int, exp: int, seed: int, shape2: bool) -> None:
    x = np.random.default_rng(seed).standard_normal(m) * 10.0 ** exp
    X = x.reshape(m, 1) if shape2 else x
    up = fro_upper(X) * (1.0 + 2.0 * gamma(m + 2))   # the callers' relative factor
    assert Fraction(up) ** 2 >= _exact_sq(x)


def test_plain_norm_is_below_the_exact_one_where_squares_underflow() -> None:
    """Entries ~1e-165: every square underflows to 0 or a few eta, the computed norm is far below the
    exact one (beyond any relative factor), and fro_upper is not."""
    x = np.full(16, 1e-165)
    exact_sq = _exact_sq(x)
    assert Fraction(fro_norm(x) * (1.0 + 2.0 * gamma(18))) ** 2 < exact_sq
    assert Fraction(fro_upper(x)) ** 2 >= exact_sq


def test_normal_range_unchanged_beyond_the_slack() -> None:
    x = np.random.default_rng(3).standard_normal(50)
    assert fro_upper(x) >= fro_norm(x)
    assert underflow_slack(50) < 1e-160
    assert abs(fro_upper(x) - np.linalg.norm(x)) <= 1e-15 * np.linalg.norm(x)


@settings(max_examples=100, deadline=None)
@given(m=st.integers(1, 30), exp=st.integers(-175, 2), seed=st.integers(0, 2**31 - 1), scaled=st.booleans())
def test_balanced_vector_norm_bounds_the_exact_one_on_both_paths(m: int, exp: int, seed: int, scaled: bool) -> None:
    """The residuals' ``||diag(s) v||`` (the compiled kernel's and numpy's) at scales where the squares
    underflow (a state near 1e-165 in balanced units computes to a norm of 0 without the slack)."""
    from switchobs_core.bounds import rigorous
    from switchobs_core.numerics import dense_kernel

    rng = np.random.default_rng(seed)
    v = rng.standard_normal(m) * 10.0 ** exp
    s = np.ldexp(1.0, rng.integers(-3, 4, size=m)) if scaled else None
    # the exact sum of squares of diag(s) v (s holds powers of two: s_i v_i is exact unless it underflows)
    exact = sum(((Fraction(float(a)) * Fraction(1 if s is None else float(s[i]))) ** 2 for i, a in enumerate(v)),
                Fraction(0))
    for kernel in (dense_kernel.NORM, None):
        saved = dense_kernel.NORM
        dense_kernel.NORM = kernel
        try:
            got = rigorous._norm(v, s)
        finally:
            dense_kernel.NORM = saved
        assert Fraction(got * (1.0 + 2.0 * gamma(m + 2))) ** 2 >= exact, (kernel, got)
