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
    """``dt b`` subnormal, then times a large ``w`` (1.8774e-22 for 1.9107e-22, 0 for 4.9e-25 before the
    scaling): the radius is at least the exact ``dt b w``."""
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
