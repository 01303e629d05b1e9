"""The sparse sandwich ``Phi~ S Phi~'`` with its transpose in a given scratch array and the result written
over its first product (:meth:`SparseTransition.sandwich_either`, ``scratch``): the doubles of the form
with new arrays, whatever the scratch held, in either memory order of ``S``; a scratch of another shape
or order, or ``S`` itself, is not used (hypothesis)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds.kalman_map import SparseTransition
from switchobs_core.numerics.csr import csr_matmat


def _phi(n: int, rng: np.random.Generator) -> np.ndarray:
    Phi = np.eye(n) * rng.uniform(0.5, 1.5, n)
    for i in range(0, n - 1, 2):        # bodies of two states: position and velocity
        Phi[i, i + 1] = rng.uniform(-0.1, 0.1)
    return Phi


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 50), fortran=st.booleans(),
       scratch=st.sampled_from(["kept", "other shape", "fortran", "S", "none"]))
def test_sandwich_in_a_scratch_is_the_new_arrays(seed, n, fortran, scratch):
    rng = np.random.default_rng(seed)
    sp = SparseTransition(_phi(n, rng))
    X = rng.standard_normal((n, n))
    S = X @ X.T + 0.01 * rng.standard_normal((n, n))
    if fortran:
        S = np.asfortranarray(S)
    ref = sp.sandwich_either(S.copy(order="K"))
    kept = {"kept": rng.standard_normal((n, n)), "other shape": np.zeros((n + 1, n + 1)),
            "fortran": np.asfortranarray(rng.standard_normal((n, n))), "S": S, "none": None}[scratch]
    before = S.copy(order="K")
    got = sp.sandwich_either(S, kept)
    assert np.array_equal(got, ref) and got.flags.c_contiguous
    assert got is not kept and np.array_equal(S, before)       # S is read only, the result is new
    assert np.array_equal(got, sp.csr @ (sp.csr @ (S if not fortran else np.ascontiguousarray(S.T))).T)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), m=st.integers(1, 12), n=st.integers(1, 12), r=st.integers(1, 6))
def test_csr_matmat_into_a_kept_array(seed, m, n, r):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((m, n)) * (rng.random((m, n)) < 0.3)
    B = rng.standard_normal((n, r))
    from scipy.sparse import csr_array
    C = csr_array(A)
    out = rng.standard_normal((m, r))           # any contents: overwritten
    got = csr_matmat(C.indptr, C.indices, C.data, C.shape, B, out)
    assert got is out
    assert np.array_equal(got, csr_matmat(C.indptr, C.indices, C.data, C.shape, B))
    assert np.allclose(got, A @ B, rtol=1e-13, atol=1e-13)
