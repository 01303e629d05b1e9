"""A step's set assembled only when read whole (:class:`switchobs_core.numerics.rounding.PendingSet`):
its blocks, trace and whole matrix are the doubles of the eager assembly (``propagate_product``,
``propagate_shaped_product``), before and after its product is handed over (hypothesis)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import ErrorEllipsoid, PendingSet, assembled


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(2, 30), rho=st.sampled_from([0.0, 1e-12, 1e-3, 10.0]),
       shaped=st.booleans(), units=st.booleans(), scale=st.floats(1e-6, 1e6), take=st.booleans(),
       fortran=st.booleans(), kept=st.booleans())
def test_blocks_trace_and_whole_are_the_eager_doubles(seed, n, rho, shaped, units, scale, take, fortran, kept):
    rng = np.random.default_rng(seed)
    d = np.ldexp(1.0, rng.integers(-8, 8, n)) if units else None
    ell = ErrorEllipsoid(n, 1.0, d)
    X = rng.standard_normal((n, n))
    Z = scale * (X @ X.T + 0.1 * rng.standard_normal((n, n)))      # not quite symmetric, as a product
    if fortran:
        Z = np.asfortranarray(Z)
    w = np.abs(rng.standard_normal(n)) * scale
    G = rng.standard_normal((n, 2)) if shaped else None
    c, cz, mn = 1e-4, 3e-15, 2.5
    eager = (ell.propagate_shaped_product(Z.copy(order="K"), w, cz, rho, mn, G, c) if shaped
             else ell.propagate_product(Z.copy(order="K"), w, cz, rho, mn))
    remade = []

    def remake():
        remade.append(1)
        return Z.copy(order="K")
    p = ell.pending(Z.copy(order="K"), w, cz, rho, mn, G, c if shaped else 0.0, remake)
    assert isinstance(p, PendingSet)
    p.kept = kept
    if take:
        T = p.take()
        np.testing.assert_array_equal(T, Z)
        assert p.take() is None                 # handed over once
    k = int(rng.integers(1, n + 1))
    cols = np.sort(rng.choice(n, size=k, replace=False))
    np.testing.assert_array_equal(p.block(cols), eager[0][np.ix_(cols, cols)], strict=True)
    assert p.trace == float(np.trace(eager[0]))
    assert p.tr == eager[1]
    S = assembled(p)
    np.testing.assert_array_equal(S, eager[0], strict=True)
    assert p.full() is S
    np.testing.assert_array_equal(p.block(cols), eager[0][np.ix_(cols, cols)])
    T = p.take()        # assembled: the product (formed again after a take) is left for a taker when kept for one
    if kept:
        np.testing.assert_array_equal(T, Z)
    else:
        assert T is None
    assert len(remade) == (1 if take else 0)
