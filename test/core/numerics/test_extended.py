"""Extended-precision products by BLAS and the exponential built on them
(switchobs_core.numerics.extended), against an independent 60-digit decimal reference: the product
within its stated bound, the exponential far below double precision on random, stiff, non-normal
and badly scaled matrices, and the proven error bound of a double-precision exponential
(expm_bound) covering its real error measured against it."""

from __future__ import annotations

import decimal
import math
from decimal import Decimal

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.numerics.expm_bound import certify_zoh, expm_error_bound
from switchobs_core.numerics.extended import expm_extended, ext_matmul
from switchobs_core.numerics.scaling import balance

LD = np.longdouble
U = 2.0**-53
U_X = float(np.finfo(LD).eps) / 2
PREC = 60


def _dec(M: np.ndarray) -> list[list[Decimal]]:
    """The exact value of each extended entry (``hi + lo`` in double, both exact in Decimal)."""
    M = np.asarray(M, dtype=LD)
    hi = M.astype(float)
    lo = (M - hi).astype(float)
    return [[Decimal(float(hi[i, j])) + Decimal(float(lo[i, j])) for j in range(M.shape[1])]
            for i in range(M.shape[0])]


def _dmul(A: list, B: list) -> list:
    return [[sum((A[i][k] * B[k][j] for k in range(len(B))), Decimal(0)) for j in range(len(B[0]))]
            for i in range(len(A))]


def _dexpm(M: np.ndarray, dt: float) -> list:
    """``e^{M dt}`` in 60-digit decimal: Taylor series to 1e-58 of a scaled argument, squared back."""
    with decimal.localcontext() as ctx:
        ctx.prec = PREC
        X = [[v * Decimal(float(dt)) for v in row] for row in _dec(M)]
        n = len(X)
        s = 0
        nrm = max(sum(abs(X[i][j]) for i in range(n)) for j in range(n))
        while nrm > Decimal("0.5"):
            nrm /= 2
            s += 1
        X = [[v / 2**s for v in row] for row in X]
        E = [[Decimal(int(i == j)) for j in range(n)] for i in range(n)]
        T = [row[:] for row in E]
        for k in range(1, 200):
            T = [[v / k for v in row] for row in _dmul(T, X)]
            E = [[E[i][j] + T[i][j] for j in range(n)] for i in range(n)]
            if max(abs(v) for row in T for v in row) < Decimal(10) ** (2 - PREC):
                break
        for _ in range(s):
            E = _dmul(E, E)
        return E


def _dist(X: np.ndarray, ref: list) -> np.ndarray:
    """``|X - ref|`` entrywise, taken in Decimal and rounded once to double."""
    with decimal.localcontext() as ctx:
        ctx.prec = PREC
        D = _dec(X)
        return np.array([[float(abs(D[i][j] - ref[i][j])) for j in range(len(ref[0]))] for i in range(len(ref))])


def _matrices(draw, n: int, m: int, spread: float) -> np.ndarray:
    """An extended matrix of full 64-bit significands, entries spread over ``10^{+-spread}``."""
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, m)).astype(LD) / LD(3.0)
    return A * (LD(10.0) ** rng.uniform(-spread, spread, (n, m)).astype(LD))


@st.composite
def _pairs(draw):
    n, k, m = draw(st.integers(1, 6)), draw(st.integers(1, 12)), draw(st.integers(1, 6))
    spread = draw(st.sampled_from([0.0, 1.0, 4.0]))
    return _matrices(draw, n, k, spread), _matrices(draw, k, m, spread)


def _product_bound(A: np.ndarray, B: np.ndarray, exact: list) -> np.ndarray:
    """The module docstring's bound per entry: ``4 (2k + 3) k u 2^-beta max_row |A| max_col |B|``
    plus one extended rounding of the result."""
    k = A.shape[1]
    beta = (53 - max(1, math.ceil(math.log2(max(k, 2))))) // 2
    ra = np.abs(A).max(axis=1).astype(float)[:, None]
    cb = np.abs(B).max(axis=0).astype(float)[None, :]
    ex = np.array([[abs(float(v)) for v in row] for row in exact])
    return 4 * (2 * k + 3) * k * U * 2.0**-beta * ra * cb + 2 * U_X * ex


@settings(max_examples=60, deadline=None)
@given(_pairs())
def test_product_within_its_bound(pair):
    """Property: every entry of ``ext_matmul(A, B)`` within the stated bound of the exact product,
    full 64-bit significands and entries spread over eight decades included."""
    A, B = pair
    exact = _dmul(_dec(A), _dec(B))
    C = ext_matmul(A, B)
    assert C.dtype == LD and C.shape == (A.shape[0], B.shape[1])
    assert np.all(_dist(C, exact) <= _product_bound(A, B, exact))


def test_long_inner_dimension_is_as_accurate_as_numpy_longdouble():
    """k = 300 (fewer bits per integer part): within the bound, and no worse than numpy's own
    extended product on balanced factors."""
    rng = np.random.default_rng(5)
    A = rng.standard_normal((3, 300)).astype(LD) / LD(7.0)
    B = rng.standard_normal((300, 4)).astype(LD) / LD(3.0)
    with decimal.localcontext() as ctx:
        ctx.prec = PREC
        exact = _dmul(_dec(A), _dec(B))
    err = _dist(ext_matmul(A, B), exact)
    assert np.all(err <= _product_bound(A, B, exact))
    assert err.max() <= max(_dist(A @ B, exact).max(), 300 * U_X * 1e-3)


def test_non_finite_factors_take_numpys_product():
    A = np.array([[1.0, np.inf], [0.0, 1.0]], dtype=LD)
    B = np.eye(2, dtype=LD)
    with np.errstate(invalid="ignore"):          # inf * 0 in numpy's product
        np.testing.assert_array_equal(ext_matmul(A, B), A @ B)
    assert ext_matmul(np.zeros((2, 0), dtype=LD), np.zeros((0, 3), dtype=LD)).shape == (2, 3)


def test_decimal_reference_matches_exact_exponentials():
    """The reference itself: a diagonal and a nilpotent matrix, whose exponentials are known in closed form."""
    lam = np.array([-3.0, 0.5, 2.0])
    ref = _dexpm(np.diag(lam), 0.7)
    with decimal.localcontext() as ctx:
        ctx.prec = PREC
        for i, v in enumerate(lam):
            assert abs(ref[i][i] - (Decimal(v) * Decimal(0.7)).exp()) < Decimal(10) ** (5 - PREC)
    N = np.array([[0.0, 1.0], [0.0, 0.0]])
    assert _dexpm(N, 0.25) == [[1, Decimal(0.25)], [0, 1]]


@st.composite
def _systems(draw):
    """(M, dt): random, stiff symmetric, stiff non-normal (eigenvectors of condition up to ~10),
    or badly scaled (a random matrix in units spanning 1e-4..1e4)."""
    kind = draw(st.sampled_from(["random", "stiff", "nonnormal", "units"]))
    n = draw(st.integers(2, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    if kind == "random":
        return rng.standard_normal((n, n)), draw(st.floats(0.01, 3.0))
    if kind == "stiff":
        Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        return (Q * -(10.0 ** rng.uniform(-2, 3, n))) @ Q.T, draw(st.floats(1e-3, 0.1))
    if kind == "nonnormal":
        V = np.eye(n) + 0.4 * rng.standard_normal((n, n))
        return (V * -(10.0 ** rng.uniform(-2, 2.5, n))) @ np.linalg.inv(V), draw(st.floats(1e-3, 0.1))
    d = 10.0 ** rng.uniform(-4, 4, n)
    return (d[:, None] * rng.standard_normal((n, n))) / d[None, :], draw(st.floats(0.01, 1.0))


@settings(max_examples=40, deadline=None)
@given(_systems())
def test_exponential_within_the_rounding_of_its_squarings(case):
    """Property: ``expm_extended`` within :func:`_squaring_bound` of the decimal exponential, in the
    balanced coordinates it works in (so in any units): extended-precision rounding of the Taylor
    sum, carried through the squarings (each doubles an error times the norm of the matrix
    squared). Measured: at most a third of that bound over 300 examples (numpy's own
    ``longdouble`` products err as much: up to 10 squarings of a stiff non-normal matrix, where
    scipy's double-precision exponential errs 500-900x more)."""
    M, dt = case
    ref = _dexpm(M, dt)
    E = expm_extended(M, dt)
    err = _dist(E, ref) / _ratio(M)
    assert err.max() <= _squaring_bound(M, dt), (err.max() / _squaring_bound(M, dt))


def _squaring_bound(M: np.ndarray, dt: float) -> float:
    """The forward error of an extended-precision scaling and squaring in balanced coordinates:
    ``s`` the least with ``||X 2^-s||_1 <= 1/2``, ``delta_0 = 2 (20 + 4 n) u_x`` for the Taylor sum
    (up to 20 terms and products, each rounded by ``u_x`` of a sum below ``e^{1/2} < 2``), and
    ``delta <- 2 F delta + delta^2 + 4 n u_x F^2`` per squaring of a matrix of 2-norm ``F`` (its
    norm in double precision: a size)."""
    n = M.shape[0]
    X = M * dt / _ratio(M)
    nrm = float(np.abs(X).sum(axis=0).max())
    s = max(0, math.ceil(math.log2(nrm / 0.5))) if nrm > 0.5 else 0
    delta = 2 * (20 + 4 * n) * U_X
    for j in range(s, 0, -1):
        F = float(np.linalg.norm(expm(X * 2.0**-j), 2))
        delta = 2 * F * delta + delta * delta + 4 * n * U_X * F * F
    return delta


def _ratio(M: np.ndarray) -> np.ndarray:
    """``d_i / d_j``: ``(D^-1 X D)_ij = X_ij / (d_i / d_j)`` in the balanced coordinates."""
    d = balance(M)
    return d[:, None] / d[None, :]


def _own_error(M: np.ndarray, dt: float) -> float:
    """The 2-norm of the largest error the property above allows, in the given units."""
    return _squaring_bound(M, dt) * float(np.linalg.norm(_ratio(M)))


@settings(max_examples=30, deadline=None)
@given(_systems())
def test_certified_bound_covers_the_real_error_of_expm(case):
    """Property: the proven bound of expm_bound (what the rounding-aware bound adds per step) covers
    the distance of scipy's double-precision exponential to the extended-precision one, plus the
    latter's own error (the property above), on the same families."""
    M, dt = case
    Phi = expm(M * dt)
    truth = expm_extended(M, dt)
    diff = float(np.linalg.norm((np.asarray(Phi, dtype=LD) - truth).astype(float), 2))
    cert = certify_zoh(M, dt)
    bound = expm_error_bound(Phi, cert.E, cert.dE)
    assert diff <= bound + _own_error(M, dt), (diff, bound)
