"""The stamp-error bound (switchobs_core.bounds.stamp) against a brute force: the exact error
``C x(t + s) - C x(t)`` computed with scipy's expm on a grid of stamp errors and the worst error
direction in the ball, for random systems (hypothesis)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds import stamp as stamp_module
from switchobs_core.bounds.stamp import StampError, stamp_error_bound
from switchobs_core.model.scenarios import paper_system
from switchobs_core.numerics.scaling import balance

_F = st.floats(-3.0, 3.0, allow_nan=False)


def _achieved(A, C, x_hat, beta, d, B=None, u=None, k=41):
    """The largest ``||C (e^{As} - I) x + C Gamma(s) B u||`` found over a grid of ``|s| <= d`` and,
    per ``s``, the two ends of the ball's worst direction ``x = x_hat -/+ beta v``."""
    n = A.shape[0]
    worst = 0.0
    for s in np.linspace(-d, d, k):
        # [[A, I], [0, 0]] gives Gamma(s) in its corner block, and e^{As} - I = A Gamma(s)
        # without the cancellation of expm(A s) - I
        Z = np.zeros((2 * n, 2 * n))
        Z[:n, :n], Z[:n, n:] = A, np.eye(n)
        G = sla.expm(Z * s)[:n, n:]
        M = A @ G
        g = np.zeros(C.shape[0]) if B is None else C @ (G @ (B @ u))
        CM = C @ M
        v = np.linalg.svd(CM)[2][0] if CM.size else np.zeros(n)
        for sign in (1.0, -1.0):
            worst = max(worst, float(np.linalg.norm(CM @ (x_hat - sign * beta * v) + g)))
    return worst


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 4), p=st.integers(1, 3), seed=st.integers(0, 2**31 - 1),
       scale=st.floats(0.01, 3.0), beta=st.floats(0.0, 2.0), d=st.floats(1e-6, 0.3))
def test_the_bound_holds_against_the_brute_force(n, p, seed, scale, beta, d):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n)) * scale
    C = rng.normal(size=(p, n))
    x_hat = rng.normal(size=n) * 10.0
    got = stamp_error_bound(A, C, x_hat, beta, d)
    want = _achieved(A, C, x_hat, beta, d)
    assert got >= want * (1.0 - 1e-9), (got, want)     # the brute force's own rounding: 1e-9
    # and within the crude bound nu(C) (||x|| + beta) (a d + (a d)^2 e^{a d} / 2), with the norm
    # bounds the module uses (nu(X) = sqrt(||X||_1 ||X||_inf) >= ||X||_2)
    a = np.sqrt(np.linalg.norm(A, 1) * np.linalg.norm(A, np.inf))
    nC = np.sqrt(np.linalg.norm(C, 1) * np.linalg.norm(C, np.inf))
    crude = nC * (np.linalg.norm(x_hat) + beta) * (a * d + (a * d) ** 2 * np.exp(a * d) / 2)
    assert got <= crude * (1.0 + 1e-9) + 1e-300


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), d=st.floats(1e-5, 0.2), beta=st.floats(0.0, 1.0))
def test_the_bound_holds_with_an_input_and_in_balanced_units(seed, d, beta):
    """A camera-like system (positions in m beside velocities) with an input ``B u``, bounded in
    the balanced coordinates: the error ball is the balanced one, the brute force samples it."""
    rng = np.random.default_rng(seed)
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2:, 2:] = rng.normal(size=(2, 2)) * 0.5
    B = rng.normal(size=(4, 1))
    u = rng.normal(size=1)
    C = np.hstack([np.eye(2), np.zeros((2, 2))])
    x_hat = rng.normal(size=4) * 5.0
    se = StampError(A, B)
    got = se.bound(C, x_hat, beta, d, u)
    # a balanced ball of radius beta contains the plain ball of radius beta * min(D)
    want = _achieved(A, C, x_hat, beta * float(se.d.min()), d, B, u)
    assert got >= want * (1.0 - 1e-9), (got, want)


def test_no_stamp_error_no_measurement_error():
    A = np.array([[0.0, 1.0], [-1.0, 0.0]])
    assert stamp_error_bound(A, np.eye(2), np.ones(2), 1.0, 0.0) == 0.0


def test_a_constant_velocity_track_gives_speed_times_offset():
    """x = (p, v): C = [1 0], a 50 ms stamp error of a body at 22 m/s is a 1.1 m error to first
    order (docs: error >= speed x offset); the bound is that within its second-order terms."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    C = np.array([[1.0, 0.0]])
    got = stamp_error_bound(A, C, np.array([3.0, 22.0]), 0.0, 0.05)
    assert 1.1 <= got <= 1.1 * 1.2, got


def test_a_subnormal_rate_times_a_large_ball() -> None:
    """``A = [[k eta]]`` (``a d`` under ``2^-1022``) and a ball of ``1e300``, with a zero estimate or one
    of 1e150: the bound is at least ``a d beta`` (``<= (e^{a d} - 1) beta``) and ``d |A x_hat|``, exactly
    in rationals (``a d`` rounded down or to 0 gave 1e-164 for 7.8e-25)."""
    rng = np.random.default_rng(1)
    for _ in range(800):
        a = int(rng.integers(1, 2000)) * 5e-324
        d = float(rng.uniform(0.001, 1.0))
        x = float(rng.choice([0.0, 1e150]))
        b = StampError(np.array([[a]]), scale=np.ones(1)).bound(np.array([[1.0]]), np.array([x]), 1e300, d)
        assert Fraction(b) >= Fraction(a) * Fraction(d) * (Fraction(1e300) + Fraction(x)), (a, d, x, b)


def _exp_below(x: int, k: int = 3000) -> Fraction:
    """``<= e^x`` (``x >= 0``): the Taylor series to ``x^k / k!``, exactly."""
    term, total = Fraction(1), Fraction(1)
    for j in range(1, k + 1):
        term = term * x / j
        total += term
    return total


def test_products_under_the_normal_range_against_the_exact_error() -> None:
    """``A = [[1]]`` and long stamp errors: ``||C|| ||x_hat||`` (1e-400) and ``||C|| ||B u||`` (1e-330)
    fall under ``2^-1022`` before ``e^{a d}`` (``e^600``, ``e^700``) magnifies them. The bound is at least
    the exact error at ``s = d``, ``C (e^d - 1) x_hat`` (3.77e-140) and ``C (e^d - 1) B u`` (1.01e-26):
    the products formed in the normal range gave 0, without their rounding or the ``B u`` term less."""
    one = np.array([[1.0]])
    got = stamp_error_bound(one, np.array([[1e-200]]), np.array([1e-200]), 0.0, 600.0)
    assert Fraction(got) >= Fraction(1e-200) ** 2 * (_exp_below(600) - 1), got
    got = StampError(one, np.array([[1e-75]]), scale=np.ones(1)).bound(np.array([[1e-180]]), np.zeros(1), 0.0,
                                                                      700.0, np.array([1e-75]))
    assert Fraction(got) >= Fraction(1e-180) * Fraction(1e-75) ** 2 * (_exp_below(700) - 1), got


def test_normal_range_is_the_plain_formula(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where every partial product is normal (the paper's model, ``x_hat`` zero or not, ``beta`` zero or
    not, with an input) the bound is the plain formula's bit for bit: the same bound with every product
    formed directly (the path chosen by the factors, ``||x_hat|| = sqrt(12 eta)`` at ``x_hat = 0``, gave
    0.0016476758996162141 for 0.001647675899616213 with ``D = I``, ``beta = 0.3``, ``d = 0.005``)."""
    P = paper_system()
    se = StampError(P.A, P.B, scale=balance(P.A))
    C = np.eye(P.A.shape[0])[:2]
    rng = np.random.default_rng(4)
    cases = [(x, beta, d, u) for x in (np.zeros(P.A.shape[0]), rng.standard_normal(P.A.shape[0]))
             for beta in (0.0, 0.3) for d in (1e-4, 0.005, 0.05) for u in (None, rng.standard_normal(P.B.shape[1]))]
    got = [se.bound(C, x, beta, d, u) for x, beta, d, u in cases]
    def no_product_path(*f: float) -> float:
        raise AssertionError(f"the product path for {f}")

    monkeypatch.setattr(stamp_module, "NORMAL", 0.0)        # every product formed directly
    monkeypatch.setattr(stamp_module, "_product_up", no_product_path)
    assert got == [se.bound(C, x, beta, d, u) for x, beta, d, u in cases]


@pytest.mark.parametrize(("A", "B", "C", "x", "u", "d"), [
    ([[0.0]], None, [[-7.7e160]], [5.4e277], None, 2.7e-49),
    ([[0.0]], [[1e200]], [[0.0]], [0.0], [1e200], 1.0),
    ([[1.0]], [[1e200]], [[0.0]], [1.0], [1e200], 1e3),
    ([[0.0]], None, [[-0.0]], [1.881243722374132e234], None, 3.778781935618507e-231),
])
def test_an_overflowing_norm_times_a_zero_factor(A: list, B: list | None, C: list, x: list, u: list | None,
                                                  d: float) -> None:
    """A norm that overflows (``||C||``, ``||x_hat||``, ``||B u||``) meets a zero factor (``A = 0``,
    ``C = 0``) or a product of two norms' underflow slacks that underflows (``gamma ||C|| ||A||``): the
    bound is a number at least 0 or ``inf``, never ``nan`` (the exact error is 0)."""
    se = StampError(np.array(A), None if B is None else np.array(B), scale=np.ones(1))
    got = se.bound(np.array(C), np.array(x), 0.0, d, None if u is None else np.array(u))
    assert got >= 0.0, got


def test_product_up_bounds_the_exact_product() -> None:
    """:func:`~switchobs_core.bounds.stamp._product_up` of two to six factors whose product falls
    anywhere from ``2^-1100`` (under the subnormals) to ``2^100``: at least the exact product, in rationals
    (the mantissas' product rounds down by up to ``k - 1`` units and the scaling to a subnormal by up to
    ``eta / 2``, before the factor ``1 + 2 gamma_k`` and the added ``eta``)."""
    rng = np.random.default_rng(7)
    for _ in range(3000):
        k = int(rng.integers(2, 7))
        e = rng.integers(-300, 300, size=k)
        e[-1] = int(rng.integers(-1100, 100)) - int(e[:-1].sum())
        f = [math.ldexp(float(rng.uniform(0.5, 1.0)), int(x)) for x in e]
        if not all(0.0 < x < math.inf for x in f):
            continue
        exact = math.prod((Fraction(x) for x in f), start=Fraction(1))
        assert Fraction(stamp_module._product_up(*f)) >= exact, f
