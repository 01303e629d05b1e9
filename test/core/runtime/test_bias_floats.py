"""The bias test's CUSUM on Python floats against the same recursion on arrays, bit for bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.runtime.bias import BiasDetector, unit_normalised


class _ArrayCusum:
    """The recursion of :mod:`switchobs_core.runtime.bias` written on numpy arrays (the reference)."""

    def __init__(self, p, k_ref, h):
        self.k_ref, self.h = k_ref, h
        self.g_pos = [np.zeros(q) for q in p]
        self.g_neg = [np.zeros(q) for q in p]

    def update(self, channel, rows, s):
        i = channel - 1
        idx = slice(None) if rows is None else np.asarray(rows, dtype=int)
        s = np.asarray(s, dtype=float)
        if not np.isfinite(s).all():
            return None
        gp, gn = self.g_pos[i], self.g_neg[i]
        gp[idx] = np.maximum(0.0, gp[idx] + s - self.k_ref)
        gn[idx] = np.maximum(0.0, gn[idx] - s - self.k_ref)
        jp, jn = int(gp.argmax()), int(gn.argmax())
        if max(gp[jp], gn[jn]) <= self.h:
            return None
        sign, j, g = (1, jp, gp[jp]) if gp[jp] >= gn[jn] else (-1, jn, gn[jn])
        gp[:] = 0.0
        gn[:] = 0.0
        return (j, sign, float(g))


_S = st.floats(-12.0, 12.0, allow_nan=False) | st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1.0, -1.0])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 2), st.booleans(), st.lists(_S, min_size=4, max_size=4)),
                min_size=1, max_size=40),
       st.sampled_from([(1.0, 8.0), (0.5, 3.0), (0.0, 0.0)]))
def test_the_float_cusum_is_the_array_cusum(samples, ref):
    k_ref, h = ref
    d, a = BiasDetector((4, 3), k_ref, h), _ArrayCusum((4, 3), k_ref, h)
    for channel, some, s in samples:
        rows = [2, 0] if some else None
        s = np.array(s[:2] if some else s[:4 if channel == 1 else 3])
        alarm, want = d.update(channel, rows, s), a.update(channel, rows, s)
        assert (alarm is None) == (want is None)
        if alarm is not None:
            assert (alarm.row, alarm.sign, alarm.g) == want
        for got, ref_g in ((d.g_pos, a.g_pos), (d.g_neg, a.g_neg)):
            for x, y in zip(got, ref_g, strict=True):
                np.testing.assert_array_equal(x, y, strict=True)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(_S, min_size=4, max_size=4), min_size=1, max_size=30), st.booleans())
def test_a_list_of_floats_is_the_array_it_lists(samples, mixed):
    """``unit_normalised``'s list of Python floats is taken as it is, and a list of other numbers (ints,
    float32, ``np.float64``) as its array: the statistics and alarms of the arrays of the same doubles."""
    d, a = BiasDetector((4,)), BiasDetector((4,))
    for s in samples:
        s = [float(v) for v in s]
        if mixed:
            s[0], s[1] = np.float64(s[0]), np.float32(s[1]) if np.isfinite(s[1]) else s[1]
        arr = np.asarray(s, dtype=float)
        got, want = d.update(1, None, s), a.update(1, None, arr)
        assert (got is None) == (want is None) and (got is None or (got.row, got.sign, got.g) ==
                                                     (want.row, want.sign, want.g))
        for x, y in zip(d.g_pos + d.g_neg, a.g_pos + a.g_neg, strict=True):
            np.testing.assert_array_equal(x, y, strict=True)


def test_a_wrong_number_of_innovations_is_refused():
    d = BiasDetector((4,))
    try:
        d.update(1, [0, 1], np.zeros(3))
    except ValueError as e:
        assert "3 normalised innovations for 2 rows" in str(e)
    else:
        raise AssertionError("accepted 3 values for 2 rows")


_V = st.floats(-1e3, 1e3, allow_nan=False) | st.sampled_from([0.0, -0.0, np.nan, np.inf, 1e-300])


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(_V, st.floats(-1.0, 4.0), st.floats(0.0, 2.0)), min_size=1, max_size=4),
       st.sampled_from([None, 0.0, 0.03, 3.0]))
def test_unit_normalised_is_the_arrays_diagonal(rows, v_max):
    nu = np.array([r[0] for r in rows])
    P = np.diag([r[1] for r in rows]) + 0.25 * (1 - np.eye(len(rows)))      # off-diagonal entries do not count
    R = np.diag([r[2] for r in rows])
    with np.errstate(all="ignore"):
        sd = np.sqrt(np.maximum(np.diagonal(P + R), 0.0))
        if v_max is not None:
            sd = np.maximum(sd, v_max / 3.0)
        want = nu / sd
    got = unit_normalised(nu, P, np.diagonal(R).tolist(), v_max)
    if got is None:     # a zero spread: the arrays' values are not finite, the update ignores them
        assert not np.isfinite(want).all() and (sd == 0.0).any()
    else:
        np.testing.assert_array_equal(np.array(got), want)

def test_float32_innovations_are_summed_as_doubles():
    """float32 entries of a list are taken as the doubles they hold (as the array's), not summed in single
    precision: three values whose float32 running sum differs from the doubles'."""
    d, a = BiasDetector((4,)), BiasDetector((4,))
    for v in (2.6100058555603027, 2.6158816814422607, 2.030651092529297):
        s = [0.0, np.float32(v), 0.0, 0.0]
        d.update(1, None, s)
        a.update(1, None, np.asarray(s, dtype=float))
    for x, y in zip(d.g_pos + d.g_neg, a.g_pos + a.g_neg, strict=True):
        np.testing.assert_array_equal(x, y, strict=True)
