"""switchobs_core.runtime.consistency.InnovationTest: the innovation test of a system's channels against
the observer's prior (the exact bound's set, or the noise bound's with a declared noise_max)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.runtime.consistency import InnovationTest, check_innovation, output_rows, spectral_norm


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 10), N=st.integers(2, 4),
       noisy=st.booleans(), ellipsoid=st.booleans())
def test_check_is_check_innovation_of_the_channel_rows(seed, n, N, noisy, ellipsoid):
    """For any channel, rows and prior: the test's outcome is check_innovation's with C_r those
    rows of C_c and the bound the declared noise picks (the noise bound with noise_max, else the
    exact bound), bit for bit."""
    rng = np.random.default_rng(seed)
    p = [int(rng.integers(1, 5)) for _ in range(N)]
    C = [rng.standard_normal((pi, n)) for pi in p]
    vmax = tuple(float(v) for v in rng.uniform(0.0, 1e-2, N)) if noisy else None
    test = InnovationTest(C, vmax)
    if ellipsoid:
        A = rng.standard_normal((n, n))
        exact, noise = A @ A.T, 2.0 * A @ A.T
    else:
        exact, noise = float(rng.uniform(0.1, 2.0)), float(rng.uniform(2.0, 4.0))
    x = rng.standard_normal(n)
    c = int(rng.integers(1, N + 1))
    rows = None if rng.random() < 0.5 else tuple(sorted(rng.choice(p[c - 1], size=1).tolist()))
    C_r = output_rows(C[c - 1], rows)
    y = C_r @ x + rng.standard_normal(C_r.shape[0]) * 0.1
    got = test.check((x, exact, noise if noisy else None), c, rows, y)
    want = check_innovation(C_r, c, noise if noisy else exact, vmax[c - 1] if noisy else 0.0, x, y,
                            spectral_norm(C_r))
    assert got == want or (np.isnan(got.bound) and np.isnan(want.bound) and got.innovation == want.innovation
                           and got.allowance == want.allowance)
    # a second call reads the kept rows and norm: the same outcome
    again = test.check((x, exact, noise if noisy else None), c, rows, y)
    assert (again.innovation, again.allowance) == (got.innovation, got.allowance)


def test_an_error_inside_the_bound_passes_and_one_outside_fails():
    C = [np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])]
    test = InnovationTest(C)
    x_hat = np.zeros(3)
    ok = test.check((x_hat, 1e-3, None), 2, None, np.array([0.6e-3, 0.7e-3]))      # ||.|| = 0.92e-3
    bad = test.check((x_hat, 1e-3, None), 2, None, np.array([2e-3, 0.0]))
    assert ok.ok and ok.channel == 2
    assert not bad.ok and bad.ratio == pytest.approx(2.0, rel=1e-9)
    # one row of channel 2: only that row's error counts
    assert test.check((x_hat, 1e-3, None), 2, (1,), np.array([0.9e-3])).ok


def test_declared_noise_widens_the_allowance_by_sqrt_p_vmax():
    C = [np.eye(2), np.eye(2)]
    prior = (np.zeros(2), 1e-3, 1e-3)
    quiet = InnovationTest(C).check(prior, 1, None, np.zeros(2))
    noisy = InnovationTest(C, (0.0, 0.5)).check(prior, 2, None, np.zeros(2))
    assert noisy.allowance - quiet.allowance == pytest.approx(np.sqrt(2) * 0.5, rel=1e-9)


def test_output_rows():
    C = np.arange(12.0).reshape(3, 4)
    assert output_rows(C, None) is C
    np.testing.assert_array_equal(output_rows(C, (0, 2)), C[[0, 2]])


def test_likely_causes_are_ordered_by_the_evidence():
    """The first sample names e0 first; a gross excess a channel, bias or clock fault; a small one
    the disturbance (with its declared bound, or none) and then the noise."""
    from switchobs_core.runtime.consistency import GROSS_RATIO, likely_causes

    def order(text):
        return [c.split(" (")[0] for c in text.split(": ", 1)[1].split("; ")]

    first = likely_causes(True, 1.5, e0=2.0, noise_max=0.01, disturbance_max=None)
    assert order(first)[0] == "e0" and "exceeds e0 = 2" in first
    small = likely_causes(False, 1.5, e0=2.0, noise_max=0.01, disturbance_max=0.2)
    assert order(small) == ["disturbance", "noise", "bias", "clock", "channel"]
    assert "disturbance.max = 0.2" in small and "noise.max = 0.01" in small
    gross = likely_causes(False, GROSS_RATIO * 2, e0=2.0, noise_max=None, disturbance_max=None)
    assert order(gross) == ["channel", "bias", "clock", "disturbance", "noise"]
    assert "no disturbance.max declared" in gross and "noise (none declared)" in gross
