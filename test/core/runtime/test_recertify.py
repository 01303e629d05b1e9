"""A bound certified from a window of data: it holds for every noise within the bound (corners of
the box included), the window needs a full cycle of every channel, data that no trajectory of the
model explains within noise_max are refused, and the rows' error allowance covers their real error."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import expm_extended
from switchobs_core.runtime.recertify import DataWindow

RATE = 25.0
VMAX = 0.03


def _channel(t: float) -> int:
    return 1 if (t % 2.0) < 1.2 - 1e-9 else 2


def _fill(paper, x0, seconds, noise, *, jump=None, window=None):
    """Feed the exact plant's samples (noise(k, p) added) to a window; returns (window, x(t_last))."""
    w = DataWindow(paper.A, 2.0) if window is None else window
    x = None
    for k in range(int(seconds * RATE) + 1):
        t = k / RATE
        x = np.asarray(expm_extended(paper.A, t) @ np.asarray(x0, dtype=np.longdouble), dtype=float)
        c = _channel(t)
        y = paper.C[c - 1] @ x + noise(k, 4)
        if jump is not None and t >= jump:
            y[2] += 1.0
        w.add(t, paper.C[c - 1], y, VMAX, c)
    return w, x


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), corner=st.booleans())
def test_the_certified_radius_holds_for_noise_within_the_bound(paper, seed, corner):
    rng = np.random.default_rng(seed)
    x0 = rng.normal(scale=3.0, size=paper.n)
    if corner:      # the extreme case: every row at +-v_max
        noise = lambda k, p: VMAX * rng.choice([-1.0, 1.0], size=p)
    else:
        noise = lambda k, p: rng.uniform(-VMAX, VMAX, size=p)
    w, x = _fill(paper, x0, 2.0, noise)
    cert = w.certificate([1, 2])
    assert cert is not None
    assert np.linalg.norm(x - cert.x_ls) <= cert.radius
    # the observer's bound from any estimate: its distance to the fit plus the radius
    x_hat = x + rng.normal(scale=0.5, size=paper.n)
    assert np.linalg.norm(x - x_hat) <= cert.bound(x_hat)
    assert cert.radius < 2.0        # one cycle of 3 cm noise fixes the state to within metres, not worse
    assert cert.t == 2.0 and cert.t_start == 0.0


def test_no_certificate_before_a_full_cycle_of_every_channel(paper):
    rng = np.random.default_rng(0)
    w, _ = _fill(paper, np.ones(paper.n), 1.9, lambda k, p: rng.uniform(-VMAX, VMAX, size=p))
    assert w.certificate([1, 2]) is None          # 1.9 s < one cycle
    w.add(2.0, paper.C[0], np.zeros(4), VMAX, 1)
    assert w.ready([1, 2])
    w2 = DataWindow(paper.A, 1.0)
    for k in range(40):                            # 1.56 s of channel 1 only: agent 2 is not seen
        w2.add(k / RATE, paper.C[0], np.zeros(4), VMAX, 1)
    assert not w2.ready([1, 2]) and w2.certificate([1, 2]) is None


def test_data_the_model_cannot_explain_are_refused(paper):
    rng = np.random.default_rng(1)
    w, _ = _fill(paper, np.ones(paper.n), 2.0, lambda k, p: rng.uniform(-VMAX, VMAX, size=p), jump=1.0)
    assert w.certificate([1, 2]) is None
    assert w.refused == 1 and "refused" in w.last_refusal


def test_samples_older_than_the_window_are_dropped(paper):
    rng = np.random.default_rng(2)
    w, _ = _fill(paper, np.ones(paper.n), 3.0, lambda k, p: rng.uniform(-VMAX, VMAX, size=p),
                 window=DataWindow(paper.A, 2.0, keep=1.0))
    assert w.t_start == 1.0
    w.clear()
    assert len(w) == 0 and w.t is None


def test_the_rows_error_allowance_covers_the_rows_real_error(paper):
    w, _ = _fill(paper, np.ones(paper.n), 2.0, lambda k, p: np.zeros(p))
    for t_i in (0.0, 0.52, 1.36, 2.0):
        sel = np.flatnonzero(w.t_row == t_i)
        c = int(w.ch_row[sel[0]])
        exact = (np.asarray(paper.C[c - 1], dtype=np.longdouble) / VMAX) @ expm_extended(paper.A, t_i - 2.0)
        real = np.sqrt(np.sum(np.asarray(w.R[sel] - exact, dtype=float) ** 2, axis=1))
        assert np.all(real <= w.delta[sel])
    assert w.delta.max() < 1e-10        # the allowance stays near the rounding level


def _radius_without_stamps(w: DataWindow) -> float:
    """The radius of the module docstring (``||R' r|| + Delta ||r||`` over ``s^2`` plus ``Delta ||x_c|| +
    sqrt(m) + eps_y`` over ``s``) from the window's rows, with no stamp error: each quantity from its
    definition, as the certificate bounds it."""
    from switchobs_core.numerics.rounding import UNDERFLOW, gamma
    from switchobs_core.runtime.recertify import _U, _UP, _norm

    R, y = w.R, w.y
    m, n = R.shape
    x = np.linalg.lstsq(R, y, rcond=None)[0]
    G = R.T @ R
    fro2 = float(np.einsum("ij,ij->", R, R)) * (1.0 + gamma(m * n + 2))
    low = (float(np.linalg.eigvalsh(0.5 * (G + G.T))[0]) - gamma(m + 2) * fro2
           - 2 * n * _U * _norm(0.5 * (G + G.T)) - 4 * n * UNDERFLOW) / _UP
    delta = _norm(w.delta)
    s = np.sqrt(low) / _UP - delta
    res = y - R @ x
    err = _norm(gamma(n + 1) * (np.abs(R) @ np.abs(x) + np.abs(y))) * _UP
    nres = _norm(res)
    top = _norm(R.T @ res) + gamma(m + 2) * np.sqrt(fro2) * nres + np.sqrt(fro2) * err
    tail = delta * _norm(x) + np.sqrt(m) * _UP + _norm(w.ey) + _norm(np.zeros(m))
    return ((top + delta * (nres + err)) / (s * s) + tail / s) * _UP * _UP


def test_the_radius_without_a_clock_tolerance_has_no_stamp_term(paper):
    """No clock tolerance declared: the certificate's radius is the docstring's, bit for bit (not divided
    by ``1 - q`` of a stamp term that is 0, as an underflow allowance on the zero rows would make it)."""
    rng = np.random.default_rng(0)
    w, _ = _fill(paper, rng.normal(scale=3.0, size=paper.n), 2.0, lambda k, p: rng.uniform(-VMAX, VMAX, size=p))
    cert = w.certificate([1, 2])
    assert cert is not None and cert.radius == _radius_without_stamps(w)
