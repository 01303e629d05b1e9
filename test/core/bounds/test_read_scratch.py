"""The amortised bound read's ``D = S - c S_a`` in a kept array: the doubles of a new array, whatever
the array held before; a kept array of another shape or order is not used."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds.read import AnchoredBound, _minus_scaled
from switchobs_core.numerics.rounding import ErrorEllipsoid


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 10), seed=st.integers(0, 2 ** 32 - 1), c=st.floats(0.0, 10.0),
       out=st.sampled_from(["same", "other shape", "fortran", "none"]))
def test_minus_scaled_into_a_kept_array_is_the_new_arrays(n, seed, c, out):
    rng = np.random.default_rng(seed)
    S, Sa = rng.standard_normal((n, n)), rng.standard_normal((n, n))
    kept = {"same": rng.standard_normal((n, n)), "other shape": np.zeros((n + 1, n + 1)),
            "fortran": np.asfortranarray(rng.standard_normal((n, n))), "none": None}[out]
    got = _minus_scaled(S, c, Sa, kept)
    assert np.array_equal(got, _minus_scaled(S, c, Sa))
    usable = kept is not None and kept.shape == S.shape and kept.flags.c_contiguous    # (a 1 x 1 is both orders)
    assert (got is kept) == usable and (usable or out != "same")


def _ellipsoids(n: int, k: int, seed: int):
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((n, n))
    S = B @ B.T + n * np.eye(n)
    for _ in range(k):
        M = np.eye(n) + rng.choice([0.0005, 0.002, 0.02]) * rng.standard_normal((n, n))
        S = M @ S @ M.T + 0.001 * np.eye(n)
        ell = ErrorEllipsoid(n, 1.0)
        ell.S, ell.tr = S, float(np.trace(S)) * (1 + 1e-12)
        yield ell


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1))
def test_reads_with_the_kept_array_are_those_with_new_arrays(seed):
    """Property: a sequence of reads (anchors, Frobenius and Gershgorin reads) gives the same bounds as
    reads that make ``D`` anew every time."""
    import switchobs_core.bounds.read as read

    kept, fresh = AnchoredBound(), AnchoredBound()
    original = read._minus_scaled
    for ell in _ellipsoids(45, 40, seed):
        a = kept.read(ell)
        read._minus_scaled = lambda S, c, Sa, out=None: original(S, c, Sa)
        try:
            b = fresh.read(ell)
        finally:
            read._minus_scaled = original
        assert a == b
    assert kept.anchors == fresh.anchors and kept.anchors < kept.reads
