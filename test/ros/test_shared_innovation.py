"""The screening shares the innovation test's innovation with the bias test only when both tests read the
same output matrices (the same doubles, C-contiguous: ``C_r @ x`` gives the same doubles from either)."""

from __future__ import annotations

import numpy as np

from switchobs_ros.screening import same_outputs


def test_same_outputs_asks_for_the_same_doubles_in_the_same_layout():
    rng = np.random.default_rng(0)
    C = (rng.standard_normal((4, 9)), rng.standard_normal((2, 9)))
    copies = tuple(c.copy() for c in C)
    assert same_outputs(C, copies)
    assert not same_outputs(C, copies[:1])                              # another number of channels
    assert not same_outputs(C, (np.asfortranarray(C[0]), C[1]))         # another layout
    off = (C[0].copy(), C[1].copy())
    off[1][1, 3] = np.nextafter(off[1][1, 3], np.inf)                   # one double apart
    assert not same_outputs(C, off)
    assert not same_outputs(C, (C[0].astype(np.float32), C[1]))         # another dtype
