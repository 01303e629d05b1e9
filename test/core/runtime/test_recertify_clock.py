"""A window of samples whose stamps are off by up to a declared clock tolerance: the certified
radius holds (the samples were taken at ``t_i + delta_i``, ``|delta_i| <= d``), a constant offset
that fits the model exactly included; without the declaration the same window certifies a radius
the error exceeds (the case the term exists for); a tolerance that swamps the rows certifies
nothing; re-certification reads the observer's declared tolerance."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.rounding import expm_extended
from switchobs_core.runtime.recertify import DataWindow

RATE = 25.0
VMAX = 0.01


def _channel(t: float) -> int:
    return 1 if (t % 2.0) < 1.2 - 1e-9 else 2


def _window(paper, x0, delta, noise, clock):
    """Samples of the exact plant taken at ``t + delta(k)`` and stamped ``t``; returns the window
    (clock tolerance ``clock``) and the true ``x(t_last)``."""
    w = DataWindow(paper.A, 2.0)
    w.clock = clock
    x0 = np.asarray(x0, dtype=np.longdouble)
    for k in range(int(2.0 * RATE) + 1):
        t = k / RATE
        c = _channel(t)
        x_taken = np.asarray(expm_extended(paper.A, t + delta(k)) @ x0, dtype=float)
        w.add(t, paper.C[c - 1], paper.C[c - 1] @ x_taken + noise(k, 4), VMAX, c)
    return w, np.asarray(expm_extended(paper.A, 2.0) @ x0, dtype=float)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), d=st.sampled_from([1e-3, 5e-3, 2e-2]), constant=st.booleans())
def test_the_radius_holds_for_stamps_within_the_clock_tolerance(paper, seed, d, constant):
    rng = np.random.default_rng(seed)
    x0 = rng.normal(scale=10.0, size=paper.n)
    offset = rng.choice([-d, d])
    delta = (lambda k: offset) if constant else (lambda k: rng.uniform(-d, d))
    w, x = _window(paper, x0, delta, lambda k, p: rng.uniform(-VMAX, VMAX, size=p), d)
    cert = w.certificate([1, 2])
    assert cert is not None, w.last_refusal
    assert np.linalg.norm(x - cert.x_ls) <= cert.radius


def test_an_offset_the_model_fits_is_only_covered_by_the_declared_tolerance(paper):
    """Every stamp 20 ms late: the samples are those of x(t + 20 ms), which the model fits exactly,
    so only the clock term can cover the error."""
    rng = np.random.default_rng(3)
    x0 = rng.normal(scale=10.0, size=paper.n)
    no_noise = lambda k, p: np.zeros(p)
    bare, x = _window(paper, x0, lambda k: 0.02, no_noise, 0.0)
    cert = bare.certificate([1, 2])
    assert cert is not None
    err = float(np.linalg.norm(x - cert.x_ls))
    assert err > 2.0 * cert.radius            # undeclared: a radius the error is outside
    declared, _ = _window(paper, x0, lambda k: 0.02, no_noise, 0.02)
    cert = declared.certificate([1, 2])
    assert cert is not None
    assert err <= cert.radius
    assert cert.radius < 100.0 * err          # and not vacuous


def test_a_tolerance_that_swamps_the_rows_certifies_nothing(paper):
    rng = np.random.default_rng(5)
    w, _ = _window(paper, rng.normal(size=paper.n), lambda k: 0.0,
                   lambda k, p: rng.uniform(-VMAX, VMAX, size=p), 10.0)
    assert w.certificate([1, 2]) is None
    assert "clock tolerance" in w.last_refusal


def test_recovery_reads_the_observers_clock_tolerance_and_its_bound_holds(paper):
    """Every stamp 40 ms late, a clock tolerance of 40 ms declared to the observer, e0 unknown: the
    re-certified bound holds at every sample after it (velocities of metres per second: the stamps'
    error is about 0.5 m, far above the declared noise; without the clock term the certified radius is
    below that error)."""
    from scipy.linalg import expm

    from switchobs_core.design.kalman import design_kalman
    from switchobs_core.model.noise import NoiseModel
    from switchobs_core.model.schedule import Cycle, PeriodicSchedule
    from switchobs_core.runtime.observer import SwitchedObserver
    from switchobs_core.runtime.recovery import Recovery
    from switchobs_core.table.gains import kalman_table

    rate, cyc, vmax, late = 50.0, Cycle.from_ts(2.0, 0.6), 0.01, 0.04
    nm = NoiseModel(meas_std=((0.01,) * 4,) * 2, Q_c=1e-4 * np.eye(12), P0=100 * np.eye(12))
    table = kalman_table(paper, [design_kalman(paper, cyc, rate, nm)])
    x0 = np.array([0, 0, 5, -4, 1, 2, 6, -3, -1, 3, 4, 5], float)
    obs = SwitchedObserver(paper, table, "periodic", [cyc], x0=x0 + 3.0, e0=None, noise_max=vmax)
    obs.rounding.clock(late)
    rec = Recovery(obs, bias=False)
    sched, rng = PeriodicSchedule(cyc), np.random.default_rng(7)
    certified, checked = None, 0
    for k in range(int(5.0 * rate) + 1):
        t = k / rate
        c = sched.channel_at(t)
        y = paper.C[c - 1] @ (expm(paper.A * (t + late)) @ x0) + rng.uniform(-vmax, vmax, 4)
        obs.update(t, c, y)
        if rec.after(t, c, None, y, certified is not None) is not None:
            certified = t
        assert rec.window.clock == late
        if certified is not None:
            x = expm(paper.A * t) @ x0
            assert np.linalg.norm(obs.x_hat - x) <= obs.envelope().noise_bound
            checked += 1
    assert certified is not None and checked >= 100
