"""Rows that select the seen states in order (a camera's position rows): the tests read the
block as it is (:func:`switchobs_core.runtime.consistency.block_product`), with the numbers of the
products ``C_r B C_r'`` (hypothesis), and the innovation test's outcome is the general path's."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid, gamma, largest_eigenvalue
from switchobs_core.runtime.consistency import (
    InnovationTest,
    block_product,
    check_innovation,
    is_unit,
    projected_bound,
    seen_columns,
    spectral_norm,
    squared_norm,
)


def test_is_unit_only_for_the_identity():
    assert is_unit(np.eye(3))
    assert not is_unit(np.eye(3)[[1, 0, 2]])           # the rows out of the columns' order
    assert not is_unit(2.0 * np.eye(2))
    assert not is_unit(np.eye(3)[:2])


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**31), p=st.integers(1, 6), scale=st.floats(1e-300, 1e300),
       bad=st.sampled_from([None, np.inf, -np.inf, np.nan]))
def test_the_block_as_it_is_has_the_products_numbers(seed, p, scale, bad):
    """A finite block: the dense products' numbers (equal, a zero's sign aside); one that is not
    finite takes the products (their NaNs where 0 * inf makes them)."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((p, p)) * scale
    B = X + X.T
    if bad is not None:
        B[int(rng.integers(p)), int(rng.integers(p))] = bad
    I = np.eye(p)
    with np.errstate(all="ignore"):
        want = I @ B @ I.T
        got = block_product(I, B, unit=True)
    np.testing.assert_array_equal(got, want)
    if np.isfinite(B).all():
        assert got is B


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), agents=st.integers(4, 12), noisy=st.booleans(), rho=st.sampled_from([0.0, 1e-9]))
def test_selector_rows_on_a_pending_set_give_the_general_outcome(seed, agents, noisy, rho):
    """Each channel's rows select two states of one agent (n = 4 agents): the test against a pending
    set equals ``check_innovation`` without the kept identity, bit for bit."""
    rng = np.random.default_rng(seed)
    n = 4 * agents
    C = []
    for a in range(agents):
        Ci = np.zeros((2, n))
        Ci[0, 4 * a], Ci[1, 4 * a + 1] = 1.0, 1.0
        C.append(Ci)
    vmax = tuple(float(v) for v in rng.uniform(0.0, 1e-2, agents)) if noisy else None
    ell = ErrorEllipsoid(n, 1.0, None)
    X = rng.standard_normal((n, n))
    Z = X @ X.T + 1e-3 * rng.standard_normal((n, n))
    w = np.abs(rng.standard_normal(n))
    S = ell.pending(Z, w, 3e-15, rho, 2.5)
    x = rng.standard_normal(n)
    c = int(rng.integers(1, agents + 1))
    y = C[c - 1] @ x + rng.standard_normal(2) * (10.0 if rng.random() < 0.3 else 0.1)
    test = InnovationTest(C, vmax)
    got = test.check((x, S, S if noisy else None), c, None, y)
    cols = seen_columns(C[c - 1])
    assert cols is not None and is_unit(C[c - 1][:, cols])
    want = check_innovation(C[c - 1], c, S, vmax[c - 1] if noisy else 0.0, x, y, spectral_norm(C[c - 1]), cols,
                            unit=False)
    assert (got.innovation, got.allowance) == (want.innovation, want.allowance)
    assert got.ok == want.ok


def _projected_reference(C_r, S, cols, unit):
    """``projected_bound`` on a pending set as written with the block's finiteness checked first
    (``block_product``, then the symmetric part, its norm and its eigenvalue)."""
    p, n = C_r.shape
    P = block_product(C_r[:, cols], S.block(cols), unit)
    P = 0.5 * (P + P.T)
    fP = math.sqrt(float((P * P).sum()))
    lam = largest_eigenvalue(P)
    lam = max(lam, 0.0) + gamma(2 * n + 2) * squared_norm(C_r) * abs(S.trace) + 2 * p * UNIT_ROUNDOFF * fP
    return math.sqrt(lam) * (1.0 + 1e-12)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), bad=st.sampled_from([None, np.inf, -np.inf, np.nan, 1e308, -1e308]),
       diagonal=st.booleans())
def test_unit_rows_read_the_block_finiteness_off_its_norm(seed, bad, diagonal):
    """The unit path takes the block as it is and reads its finiteness off the norm of its symmetric part
    (finite only when every entry is): the doubles of the path that checks the block first, for finite
    blocks, blocks with an infinite or NaN entry (the products' numbers) and finite ones whose norm
    overflows (the block itself)."""
    rng = np.random.default_rng(seed)
    n = 12
    C_r = np.zeros((2, n))
    C_r[0, 4], C_r[1, 5] = 1.0, 1.0
    cols = seen_columns(C_r)
    ell = ErrorEllipsoid(n, 1.0, None)
    X = rng.standard_normal((n, n))
    Z = X @ X.T
    if bad is not None:
        i, j = (4, 4) if diagonal else (4, 5)
        Z[i, j] = bad
    S = ell.pending(Z, np.abs(rng.standard_normal(n)), 3e-15, 0.0, 2.5)
    with np.errstate(all="ignore"):
        want = _projected_reference(C_r, S, cols, True)
        got = projected_bound(C_r, S, cols, unit=True)
        general = projected_bound(C_r, S, cols, unit=False)
    assert got == want or (math.isnan(got) and math.isnan(want))
    if bad is None:
        assert got == general
