"""The set's n x n assembly in its fused form (:meth:`ErrorEllipsoid._apply`: the transpose copied into
a kept scratch, the halving folded into the scaling ``alpha``) against the general form it replaces,
``Z += Z'; Z *= 1/2; Z *= alpha; Z += tb Q; diag += q`` (hypothesis over sizes, memory orders, scales,
residuals and the added noise set): the same doubles wherever the halved entries are normal, within
one smallest subnormal per entry below that (one rounding instead of two, inside the plan's underflow
allowance), exactly symmetric, and the same doubles as the pending set's blocks."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import UNDERFLOW, ErrorEllipsoid


def _general(Z: np.ndarray, plan: tuple) -> np.ndarray:
    """The general assembly, pass by pass (the reference)."""
    alpha, tb, Q, q, _, _ = plan
    Z = Z.copy(order="K")
    Z += Z.T
    Z *= 0.5
    if alpha != 1.0:
        Z *= alpha
    if Q is not None:
        Z += tb * Q
    Z[np.diag_indices(Z.shape[0])] += q
    return Z


def _plan(ell: ErrorEllipsoid, Z: np.ndarray, rng: np.random.Generator, rho: float, shaped: bool) -> tuple:
    n = Z.shape[0]
    w = np.abs(rng.standard_normal(n)) * float(np.sqrt(np.abs(Z).max()))
    noise = (rng.standard_normal((n, 2)), 1e-4, None) if shaped else None
    return ell._plan(Z.diagonal(), w, 3e-15, rho, noise, 2.5)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 40), rho=st.sampled_from([0.0, 1e-12, 1e-3, 10.0]),
       shaped=st.booleans(), fortran=st.booleans(), scale=st.floats(1e-150, 1e150))
def test_fused_assembly_is_the_general_one(seed, n, rho, shaped, fortran, scale):
    rng = np.random.default_rng(seed)
    ell = ErrorEllipsoid(n, 1.0, np.ldexp(1.0, rng.integers(-6, 6, n)))
    X = rng.standard_normal((n, n))
    Z = scale * (X @ X.T + 0.1 * rng.standard_normal((n, n)))      # not quite symmetric, as a product
    if fortran:
        Z = np.asfortranarray(Z)
    plan = _plan(ell, Z, rng, rho * scale ** 0.5, shaped)
    ref = _general(Z, plan)
    got, tr = ell._apply(Z.copy(order="K"), plan)
    assert np.array_equal(got, ref)
    assert np.array_equal(got, got.T)
    assert tr == plan[5]
    cols = np.sort(rng.choice(n, size=min(n, 4), replace=False))
    assert np.array_equal(ell._block(Z.copy(order="K"), plan, cols), ref[np.ix_(cols, cols)])
    again, _ = ell._apply(Z.copy(order="K"), plan)     # the scratch reused: the same doubles
    assert np.array_equal(again, ref)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 20), shaped=st.booleans())
def test_fused_assembly_below_normal_numbers(seed, n, shaped):
    """Halved entries in the subnormal range: the fused scaling rounds once, the general form twice;
    they differ by at most one smallest subnormal per entry (each rounding errs by at most half of
    it), which the plan's underflow allowance (``(n + 4) n eta`` per step on the diagonal) covers."""
    rng = np.random.default_rng(seed)
    ell = ErrorEllipsoid(n, 1.0)
    X = rng.standard_normal((n, n))
    Z = 1e-310 * (X @ X.T + 0.1 * rng.standard_normal((n, n)))
    plan = _plan(ell, Z, rng, 1e-160, shaped)
    ref = _general(Z, plan)
    got, _ = ell._apply(Z.copy(), plan)
    assert np.all(np.abs(got - ref) <= UNDERFLOW)
    assert np.array_equal(got, got.T)
    assert np.all(plan[3] >= (n + 4) * n * UNDERFLOW)
