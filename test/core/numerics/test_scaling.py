"""The balancing's scaling (:mod:`switchobs_core.numerics.scaling`): LAPACK's ``gebal`` called directly gives
the bytes of ``scipy.linalg.matrix_balance``'s scaling, for matrices whose entries span many decades, with
zero rows and columns, in either memory order."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.linalg import matrix_balance

from switchobs_core.numerics.scaling import _gebal_scaling, _median, balance


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast")    # scipy's permutation of huge scalings
@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 24), seed=st.integers(0, 2**32 - 1), decades=st.integers(0, 30),
       density=st.floats(0.05, 1.0), fortran=st.booleans())
def test_gebal_scaling_is_matrix_balance_scaling(n, seed, decades, density, fortran):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) * 10.0 ** rng.uniform(-decades, decades, (n, n)) * (rng.random((n, n)) < density)
    if fortran:
        A = np.asfortranarray(A)
    _, (d, _) = matrix_balance(A, permute=False, separate=True)
    assert _gebal_scaling(A).tobytes() == np.asarray(d, dtype=float).tobytes()


@given(st.lists(st.one_of(st.integers(-300, 300).map(float), st.floats(allow_nan=True, allow_infinity=True)),
                max_size=40))
@example([-0.0])
@example([0.0, -0.0])
def test_median_is_numpys(values):
    e = np.array(values, dtype=float)
    want = np.median(e) if e.size else float("nan")
    got = _median(e)
    assert (np.isnan(want) and np.isnan(got)) or np.float64(got).tobytes() == np.float64(want).tobytes(), (got, want)


def test_balance_of_a_badly_scaled_pair_is_powers_of_two_that_balance_it():
    """A 2 x 2 coupling with entries 1e-6 and 1e6: ``d`` powers of two, and ``D^-1 A D`` has entries within
    a factor 4 of each other off the diagonal (gebal's radix-2 steps), where ``A``'s span 1e12."""
    A = np.array([[0.0, 1e6], [1e-6, 0.0]])
    d = balance(A)
    assert np.all(np.frexp(d)[0] == 0.5)
    Ab = A * d[None, :] / d[:, None]
    off = abs(Ab[0, 1]) / abs(Ab[1, 0])
    assert 0.25 <= off <= 4.0, (d, Ab)
