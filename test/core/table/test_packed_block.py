"""A phase's prior block read from its packed row (:meth:`switchobs_core.table.kalman.KalmanPhase.P_block`,
:func:`~switchobs_core.table.kalman.packed_block_index`): the entries of the unpacked matrix, exactly,
for any columns, with the index kept per ``(n, cols)`` (hypothesis)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.table.container import unpack_symmetric
from switchobs_core.table.kalman import KalmanPhase, packed_block_index


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 40), k=st.integers(1, 6), order=st.booleans())
def test_the_packed_block_is_the_matrix_block(seed, n, k, order):
    """Sorted or unsorted columns, repeated reads: the block of the unpacked matrix, bit for bit."""
    rng = np.random.default_rng(seed)
    packed = rng.standard_normal(n * (n + 1) // 2)
    cols = rng.choice(n, size=min(k, n), replace=False)
    cols = np.sort(cols) if order else cols
    phase = KalmanPhase(1, 0.02, packed, np.zeros((n, 2)))
    want = unpack_symmetric(packed, n)[np.ix_(cols, cols)]
    np.testing.assert_array_equal(phase.P_block(cols), want, strict=True)
    again = phase.P_block(cols.copy())      # the kept index, reached through equal columns
    np.testing.assert_array_equal(again, want, strict=True)
    assert packed_block_index(n, cols) is packed_block_index(n, cols.copy())
    assert not packed_block_index(n, cols).flags.writeable
    unpacked = KalmanPhase(1, 0.02, unpack_symmetric(packed, n), np.zeros((n, 2)))
    np.testing.assert_array_equal(unpacked.P_block(cols), want, strict=True)
