"""The disturbance's reach (:mod:`switchobs_core.numerics.disturbance_reach`) where ``a h``, the step or
the products of ``B_w``, ``w`` and the step fall under the normal range: the radius against the exact
worst case in rationals, and the radius where nothing underflows against the one of the same ``d`` with
``B_w`` and ``w`` scaled by powers of two."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction

import numpy as np
import pytest

from switchobs_core.numerics import disturbance_reach as dr
from switchobs_core.numerics.frobenius import sum_slack
from switchobs_core.numerics.rounding import NORMAL


def _worst(B: np.ndarray, w: np.ndarray) -> Fraction:
    """``max ||B diag(s) w||^2`` over the vertices ``s`` of the box, exactly (``A = 0``: ``d(h) = h B
    w_bar``, ``w_bar`` in the box, largest at a vertex)."""
    n, q = B.shape
    Bf = [[Fraction(float(a)) for a in row] for row in B]
    wf = [Fraction(float(a)) for a in w]
    return max(sum((sum((Bf[i][j] * s[j] * wf[j] for j in range(q)), Fraction(0)) ** 2 for i in range(n)),
                   Fraction(0)) for s in itertools.product((-1, 1), repeat=q))


@pytest.mark.parametrize(("a", "dt"), [(5e-324, 0.4), (5e-324, 0.1), (1e-323, 0.3), (-5e-324, 0.4)])
def test_growth_with_a_subnormal_rate(a: float, dt: float) -> None:
    """``a h`` under ``2^-1022``: the growth bound is ``h`` (``(e^{a h} - 1) / a`` rounds ``a h`` down
    or to 0, 0.333 at 0.4 and 0 at 0.1); the exact reach is ``>= dt`` (``e^{a r} >= 1 - |a| r``)."""
    r = dr.DisturbanceReach(np.array([[a]]), np.array([[1.0]]), [1.0]).radius(dt)
    assert r >= dt


def test_tiny_rates_against_the_exact_worst_case() -> None:
    """Random ``A`` of a few units of ``eta`` (up to ``1e15`` of them): ``||e^{A r} - I|| <= 1e-290``, so
    the reach is at least ``dt`` times the exact largest ``||B w||`` at a vertex, less a relative
    ``1e-280``."""
    rng = np.random.default_rng(5)
    for _ in range(300):
        n, q = int(rng.integers(1, 5)), int(rng.integers(1, 3))
        A = np.round(rng.uniform(-4, 4, (n, n))) * 5e-324 * (10.0 ** float(rng.integers(0, 15)))
        B = rng.standard_normal((n, q))
        w = np.abs(rng.standard_normal(q)) + 0.1
        dt = float(10 ** rng.uniform(-4, 1))
        r = dr.DisturbanceReach(A, B, w).radius(dt)
        assert Fraction(r) ** 2 >= Fraction(dt) ** 2 * _worst(B, w) * (1 - Fraction(1, 10**280)), (A, B, w, dt)


@pytest.mark.parametrize(("b", "w", "dt"), [(1.4441009015293509e-121, 1e300, 1.3231081282984409e-201),
                                            (1.4441009015293509e-121, 1e300, 5e-324),
                                            (1e-200, 1e-130, 0.01), (0.5, 1e300, 7 * 5e-324)])
def test_products_under_the_normal_range(b: float, w: float, dt: float) -> None:
    """``dt b`` subnormal, then times a large ``w`` (without the power-of-two scaling of ``B_w`` and ``w``:
    1.8774e-22 for 1.9107e-22, 0 for 4.9e-25): the radius is at least the exact ``dt b w``."""
    r = dr.DisturbanceReach(np.zeros((1, 1)), np.array([[b]]), [w]).radius(dt)
    assert Fraction(r) >= Fraction(dt) * Fraction(b) * Fraction(w), r


def test_extreme_scales_against_the_exact_worst_case() -> None:
    """``A = 0``, ``B_w`` of entries ``1e-330..1e150`` (some zero), ``w`` of ``1e-200..1e200``, steps of
    ``1e-6..1e3`` and subnormal ones: the radius bounds the exact worst case (``inf`` allowed)."""
    rng = np.random.default_rng(3)
    for _ in range(600):
        n, q = int(rng.integers(1, 4)), int(rng.integers(1, 3))
        B = rng.standard_normal((n, q)) * 10.0 ** rng.integers(-330, 150, size=(n, q)).astype(float)
        B[rng.random((n, q)) < 0.2] = 0.0
        w = np.abs(rng.standard_normal(q)) * 10.0 ** rng.integers(-200, 200, size=q).astype(float)
        dt = float(10.0 ** rng.uniform(-6, 3)) if rng.random() < 0.8 else float(rng.integers(1, 50)) * 5e-324
        if not (np.all(np.isfinite(B)) and np.all(w > 0.0)):
            continue
        r = dr.DisturbanceReach(np.zeros((n, n)), B, w).radius(dt)
        if math.isfinite(r):
            assert Fraction(r) ** 2 >= Fraction(dt) ** 2 * _worst(B, w), (B, w, dt, r)


def test_radius_where_nothing_underflows_does_not_depend_on_the_split() -> None:
    """``B_w`` of ``1e-150`` with ``w`` of ``1e150``: no square or product underflows, and the radius is
    the one of ``B_w 2^498``, ``w 2^-498`` (the same ``d``), bit for bit (the underflow terms added
    unconditionally gave 0.022460679775097903 for 0.022460679774998)."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    B = np.array([[1e-150, 0.0], [0.0, 2e-150], [0.0, 0.0]])
    w = np.array([1e150, 1e150])
    tiny = dr.DisturbanceReach(A, B, w)
    unit = dr.DisturbanceReach(A, np.ldexp(B, 498), np.ldexp(w, -498))
    for dt in (1e-3, 0.01, 0.5):
        assert tiny.radius(dt) == unit.radius(dt)
        assert tiny.shaped(dt)[1] == unit.shaped(dt)[1]


def test_norm_slack_only_where_the_sum_is_small() -> None:
    """A computed sum of ``m`` squares at or above ``m 2^-1022`` needs no underflow term (frobenius's
    proof): the norm of entries ``1e-152`` (squares normal) is the one without it; below, it is added
    and the bound is above the exact norm."""
    v = np.full(4, 1e-152)
    s = float(v @ v)
    assert sum_slack(s, 4) == 0.0 and dr._norm_up(v) == math.sqrt(s) * (1.0 + dr.gamma(6)) * dr._UP
    v = np.full(4, 1e-160)
    assert s >= 4 * NORMAL > float(v @ v) and sum_slack(float(v @ v), 4) > 0.0
    assert Fraction(dr._norm_up(v)) ** 2 >= sum(Fraction(float(a)) ** 2 for a in v)


@pytest.mark.parametrize(("B", "w", "dt"), [([[1e-150, 1.0]], [1e300, 1e-300], 1e-200),
                                            ([[1e-216, 0.0], [1e121, 3e-31]], [1e-305, 2e62], 2.859025574650785e-188),
                                            ([[1e300, 1e-300]], [1.0, 1.0], 1e-3)])
def test_entries_more_than_2_1021_apart(B: list, w: list, dt: float) -> None:
    """``B_w`` or ``w`` spanning more than ``2^1021``: the least entries scale under ``2^-1022`` (``m_j``
    rounded up, ``B_b``'s rounding added), and the radius bounds the exact worst case (a scaling that
    kept the least entry normal left scaled entries far above 1: 2.65e-315 for 1e-50, 3.8e-15 relative
    below, NaN)."""
    B, w = np.array(B), np.array(w)
    R = dr.DisturbanceReach(np.zeros((B.shape[0],) * 2), B, w)
    r = R.radius(dt)
    assert math.isfinite(r) and Fraction(r) ** 2 >= Fraction(dt) ** 2 * _worst(B, w), r
    G, rs = R.shaped(dt)
    assert rs == rs and not np.any(np.isnan(G))


def _in_shaped_1d(G: np.ndarray, r: float, d: Fraction) -> bool:
    """Whether ``d`` (one state) lies in ``E(G G') + [-r, r]``: ``|d| <= ||G|| + r``, exactly."""
    excess = abs(d) - Fraction(r)
    return excess <= 0 or excess ** 2 <= sum(Fraction(float(g)) ** 2 for g in G.reshape(-1))


@pytest.mark.parametrize(("b", "w", "dt"), [(1e300, 1e-300, 1e-20), (1e250, 3e-250, 7e-71),
                                            (1e-300, 1e300, 1e-20), (1.0, 1e-300, 1e-30)])
def test_shaped_where_the_step_times_w_is_subnormal(b: float, w: float, dt: float) -> None:
    """``A = 0``, ``d = dt b w``: ``dt w`` under ``2^-1022`` loses up to ``eta / 2``, which ``b``
    magnifies; the set ``E(G G') + ball(r)`` holds ``d`` (``G`` formed in the user's units missed 1e-20
    by 1.1e-25)."""
    G, r = dr.DisturbanceReach(np.zeros((1, 1)), np.array([[b]]), [w]).shaped(dt)
    assert _in_shaped_1d(G, r, Fraction(dt) * Fraction(b) * Fraction(w)), (G, r)


def test_no_nan_from_an_overflowing_rate() -> None:
    """``A`` and ``B_w`` whose products overflow: ``radius`` and ``shaped`` give numbers or ``inf``, never
    ``nan`` (``G`` and ``r`` were ``nan``)."""
    R = dr.DisturbanceReach(np.array([[3.6e-256, -3.7e-62], [-2.66e-4, -9.2e-285]]),
                            np.array([[-6.87e137], [-2.37e-16]]), [4.6e125])
    G, r = R.shaped(1.84e-5)
    assert r == r and not np.any(np.isnan(G)) and R.radius(1.84e-5) == R.radius(1.84e-5)
    assert math.inf > dr.DisturbanceReach(np.zeros((1, 1)), [[1.0]], [1.0]).radius(1e200) >= 1e200


def test_shaped_where_g_is_subnormal_in_the_users_units() -> None:
    """``G`` in the user's units ``1.4 eta`` (rounds to ``eta``) with ``D = 2^-600``: the lost ``0.4 eta``
    is ``0.4 eta 2^600`` (1.7e-143) in the balanced units of the ball, and the set still holds ``d``."""
    dt, w = 2.0**-74, 1.4 * 2.0**-1000
    R = dr.DisturbanceReach(np.zeros((1, 1)), np.array([[1.0]]), [w], scale=np.array([2.0**-600]))
    G, r = R.shaped(dt)
    assert _in_shaped_1d(G * 2.0**600, r, Fraction(dt) * Fraction(w) * 2**600), (G, r)


def test_shaped_where_the_scaled_factors_underflow() -> None:
    """``A = 0``, ``n = 1000`` states each moved by ``B_w = 2^1000``, ``w = 1``, a step of ``5 eta``: in the
    scaled units ``dt m = 2.5 eta`` rounds to ``2 eta`` (``G`` is ``4/5`` of ``d``, ``||d - G|| = sqrt(n)
    2^-74``, more than the ``24 2^-74`` of the remainder's allowance). ``d`` is a multiple of ``G``'s first
    column (the second is 0), so it lies in the set where ``||d|| - ||g|| <= r``, exactly."""
    n, dt = 1000, 5 * 5e-324
    G, r = dr.DisturbanceReach(np.zeros((n, n)), np.full((n, 1), 2.0**1000), [1.0]).shaped(dt)
    g = float(G[0, 0])
    assert np.all(G[:, 0] == g) and not np.any(G[:, 1:])
    excess = Fraction(dt) * 2**1000 - Fraction(g)        # per state
    assert excess <= 0 or n * excess**2 <= Fraction(r) ** 2, (g, r)
