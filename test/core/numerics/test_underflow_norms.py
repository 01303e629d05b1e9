"""Norms where their squares or products underflow: ``expm_bound.nu``, the disturbance's reach
(:mod:`switchobs_core.numerics.disturbance_reach`: vector and matrix norms, the Gram bound, the radius)
and the re-certification's ``_norm`` bound the exact value from above at entries of 1e-160, 1e-300 and
subnormals, with the exact value computed in rationals (every double is a dyadic rational)."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest
from _exact import bounds_spectral
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics import disturbance_reach as dr
from switchobs_core.numerics.expm_bound import _nu1inf, nu
from switchobs_core.runtime import recertify

#: Entry scales: where squares underflow (1e-160), where products of two norms underflow (1e-165),
#: far below (1e-300), subnormal (1e-310, 5e-324) and a normal one (1).
SCALES = [1e-160, 1e-165, 1e-300, 1e-310, 5e-324, 1.0]


def _F(x: float) -> Fraction:
    return Fraction(float(x))


def _sq(v: np.ndarray) -> Fraction:
    """``||v||^2`` (Frobenius for a matrix) exactly."""
    return sum((_F(a) ** 2 for a in np.ravel(v)), Fraction(0))


def _one_inf(X: np.ndarray) -> tuple[Fraction, Fraction]:
    """``(||X||_1, ||X||_inf)`` exactly."""
    A = [[abs(_F(a)) for a in row] for row in X]
    cols = max(sum((A[i][j] for i in range(len(A))), Fraction(0)) for j in range(len(A[0])))
    rows = max(sum(r, Fraction(0)) for r in A)
    return cols, rows


def _matrix(rng: np.random.Generator, shape: tuple[int, int], scale: float) -> np.ndarray:
    X = rng.uniform(-1.0, 1.0, shape) * scale
    if scale < 1e-300:          # subnormal: a few units of the smallest
        X = np.round(rng.uniform(-8.0, 8.0, shape)) * 5e-324
    return X


@pytest.mark.parametrize("scale", SCALES)
def test_nu_bounds_the_exact_product_of_norms(scale: float) -> None:
    """``nu(X)^2 >= ||X||_1 ||X||_inf`` (``>= ||X||_2^2``) exactly."""
    rng = np.random.default_rng(11)
    for shape in ((1, 1), (3, 3), (4, 2), (6, 6)):
        X = _matrix(rng, shape, scale)
        if not X.any():
            X[0, 0] = 5e-324
        a, b = _one_inf(X)
        assert _F(nu(X)) ** 2 >= a * b, (shape, scale, nu(X))


def test_nu_where_the_product_of_norms_underflows() -> None:
    """Entries of 1e-165: ``sqrt(a b)`` computed is 0, ``nu`` is not."""
    X = np.full((3, 3), 1e-165)
    a, b = _nu1inf(X)
    assert math.sqrt(a * b) == 0.0 and nu(X) >= 3e-165


@settings(max_examples=120, deadline=None)
@given(n=st.integers(1, 6), m=st.integers(1, 6), exp=st.integers(-330, 2), seed=st.integers(0, 2**31 - 1))
def test_nu_bounds_the_exact_product_at_any_scale(n: int, m: int, exp: int, seed: int) -> None:
    X = np.random.default_rng(seed).standard_normal((n, m)) * 10.0 ** exp
    a, b = _one_inf(X)
    assert _F(nu(X)) ** 2 >= a * b


def test_nu_unchanged_in_the_normal_range() -> None:
    """Where ``a b`` is normal the number is ``sqrt(a b)`` rounded up, bit for bit."""
    rng = np.random.default_rng(4)
    for exp in (-150, -20, 0, 20, 150):
        X = rng.standard_normal((5, 5)) * 10.0 ** exp
        a, b = _nu1inf(X)
        assert nu(X) == math.sqrt(a * b) * (1.0 + 8.0 * 2.0**-53)


@pytest.mark.parametrize("scale", SCALES)
def test_reach_norms_bound_the_exact_ones(scale: float) -> None:
    """The disturbance's vector norm, Frobenius norm and 2-norm bound (``min(nu, ||.||_F)``) are above
    the exact norms (the 2-norm: ``b^2 I - X'X`` positive semidefinite in rationals)."""
    rng = np.random.default_rng(5)
    for shape in ((4, 1), (6, 3), (2, 2)):
        X = _matrix(rng, shape, scale)
        assert _F(dr._norm_up(X[:, 0])) ** 2 >= _sq(X[:, 0])
        assert _F(dr._mat_fro_up(X)) ** 2 >= _sq(X)
        assert bounds_spectral(dr._mat_norm_up(X), [[_F(a) for a in row] for row in X]), (shape, scale)


def _gram_exact(X: np.ndarray, m: np.ndarray) -> Fraction:
    """``m' |X'X| m`` exactly."""
    Xf = [[_F(a) for a in row] for row in X]
    n, q = X.shape
    G = [[abs(sum((Xf[k][i] * Xf[k][j] for k in range(n)), Fraction(0))) for j in range(q)] for i in range(q)]
    return sum((_F(m[i]) * G[i][j] * _F(m[j]) for i in range(q) for j in range(q)), Fraction(0))


@pytest.mark.parametrize("weight", [1.0, 1e100, 1e-150])
@pytest.mark.parametrize("scale", SCALES)
def test_reach_gram_bounds_the_exact_form(scale: float, weight: float) -> None:
    """``g(X) >= sqrt(m' |X'X| m)`` exactly, also where the Gram matrix's products underflow, with
    weights of 1 (neither underflow term needed alone), 1e100 (the entries' term) and 1e-150 (the
    form's term)."""
    rng = np.random.default_rng(6)
    m = np.array([1.0, 0.5, 2.0]) * weight
    X = _matrix(rng, (5, 3), scale)
    assert _F(dr._gram(X, m, 0.0)) ** 2 >= _gram_exact(X, m), (scale, weight)


@pytest.mark.parametrize(("entry", "weight"), [(1e-165, 1e100), (1e-100, 1e-150)])
def test_reach_gram_needs_each_underflow_term(entry: float, weight: float) -> None:
    """Entries of 1e-165 (their products underflow) with weights 1e100: the entries' term
    ``s sqrt((n + 2) eta)``; entries of 1e-100 (normal products) with weights 1e-150 (the form's
    products underflow): the form's term."""
    X = np.full((5, 3), entry)
    X[1] *= -1.0
    m = np.full(3, weight)
    assert _F(dr._gram(X, m, 0.0)) ** 2 >= _gram_exact(X, m)


@pytest.mark.parametrize("scale", [1e-160, 1e-170, 1e-300, 1e-310])
def test_reach_radius_bounds_the_exact_worst_case(scale: float) -> None:
    """``A = 0``: ``d(h) = h B w_bar`` with ``w_bar`` in the box, whose largest norm is at a vertex; the
    radius is at least that (without what underflow hides the radius is 0 at 1e-170)."""
    rng = np.random.default_rng(9)
    B = _matrix(rng, (4, 2), scale)
    B[0, 0] = scale
    m = np.array([1.0, 3.0])
    dt = 0.01
    r = dr.DisturbanceReach(np.zeros((4, 4)), B, m).radius(dt)
    Bf = [[_F(a) for a in row] for row in B]
    worst = max(sum(((Bf[i][0] * s0 * 1 + Bf[i][1] * s1 * 3) ** 2 for i in range(4)), Fraction(0))
                for s0, s1 in itertools.product((-1, 1), repeat=2))
    assert _F(r) ** 2 >= _F(dt) ** 2 * worst, (scale, r)


@pytest.mark.parametrize("scale", SCALES)
def test_recertify_norm_bounds_the_exact_one(scale: float) -> None:
    rng = np.random.default_rng(8)
    for shape in ((7,), (3, 3)):
        v = _matrix(rng, (1, int(np.prod(shape))), scale).reshape(shape)
        assert _F(recertify._norm(v)) ** 2 >= _sq(v), (shape, scale)
