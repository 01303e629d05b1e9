"""switchobs_core.runtime.consistency.InnovationTest: the innovation test of a system's channels against
the observer's prior (the exact bound's set, or the noise bound's with a declared noise_max)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import ErrorEllipsoid
from switchobs_core.runtime.consistency import (
    InnovationTest,
    check_innovation,
    innovation_allowance,
    is_unit,
    output_rows,
    seen_columns,
    spectral_norm,
)


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


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), p=st.integers(1, 4), pending=st.booleans(), noisy=st.booleans(),
       f=st.sampled_from([0.0, 0.3, 0.9, 1.0 - 1e-12, 1.0, 1.0 + 1e-12, 1.1, 3.0]))
def test_the_allowance_a_passing_sample_is_within_decides_as_the_full_one(seed, p, pending, noisy, f):
    """On an ellipsoid the test stops at the allowance with the block's largest diagonal entry (less the
    solver's error) in place of its eigenvalue when the innovation is within it: never above the full
    allowance, and the outcome is the full allowance's, for innovations of any size up to and around it."""
    rng = np.random.default_rng(seed)
    n = 12
    C_r = np.zeros((p, n))
    cols = np.sort(rng.choice(n, size=p, replace=False))
    C_r[np.arange(p), cols] = 1.0 if rng.random() < 0.5 else rng.standard_normal(p)
    X = rng.standard_normal((n, n)) * 10.0 ** rng.uniform(-6, 3)
    Z = X @ X.T
    if pending:
        S = ErrorEllipsoid(n, 1.0, None).pending(Z, np.abs(rng.standard_normal(n)), 3e-15, 0.0, 2.5)
    else:
        S = Z
    sc = seen_columns(C_r)
    unit = sc is not None and is_unit(C_r[:, sc])
    x = rng.standard_normal(n)
    v_max = float(rng.uniform(0.0, 1e-2)) if noisy else 0.0
    d = rng.standard_normal(p)
    args = (spectral_norm(C_r), sc, None, unit, None if sc is None else C_r[:, sc])
    y0 = C_r @ x
    full = innovation_allowance(C_r, S, v_max, x, y0, *args)
    y = y0 + f * full * d / np.linalg.norm(d)
    full = innovation_allowance(C_r, S, v_max, x, y, *args)           # the allowance of this sample
    got = check_innovation(C_r, 1, S, v_max, x, y, *args)
    assert got.ok == (got.innovation <= full)
    assert got.allowance <= full
    if got.allowance < full:        # stopped early: only for a sample within it
        assert got.ok and got.innovation <= got.allowance


def test_a_block_whose_squares_underflow_decides_as_the_full_one():
    """A 6 x 6 block near 2e-181 (its squares underflow: the computed ``||P||_F`` is 0) whose eigenvalue LAPACK
    can put below the largest diagonal entry, with the innovation between the two: the early stop keeps the
    solver's error term (with what underflow hides), so its allowance is never above the full one and the
    outcome is the full allowance's, whatever the eigensolver returns."""
    P = np.array([
        [2.40991986510293e-181, 3.871867898743924e-194, 8.584661763692456e-194,
         -7.563954482487255e-194, 3.570574305959242e-195, 2.958578604272695e-194],
        [3.871867898743924e-194, 1.2465278480694844e-181, 4.485865304578662e-195,
         -1.2737256992559256e-194, -2.249032334485394e-194, 3.6007177370979274e-194],
        [8.584661763692456e-194, 4.485865304578662e-195, 1.2730824886087327e-181,
         -1.5059858184852805e-194, 5.968082705313699e-194, 3.794734834876325e-194],
        [-7.563954482487255e-194, -1.2737256992559256e-194, -1.5059858184852805e-194,
         2.3434405287666358e-181, 2.1402026358941004e-194, 2.7283653225665394e-194],
        [3.570574305959242e-195, -2.249032334485394e-194, 5.968082705313699e-194,
         2.1402026358941004e-194, 2.2312344549508603e-181, -1.1399427342849382e-194],
        [2.958578604272695e-194, 3.6007177370979274e-194, 3.794734834876325e-194,
         2.7283653225665394e-194, -1.1399427342849382e-194, 2.3348401739852207e-181]])
    C, x = np.eye(6), np.zeros(6)
    y = np.array([4.909093465307709e-91, 0.0, 0.0, 0.0, 0.0, 0.0])
    full = innovation_allowance(C, P, 0.0, x, y)
    got = check_innovation(C, 1, P, 0.0, x, y)
    assert got.allowance <= full
    assert got.ok == (got.innovation <= full)
