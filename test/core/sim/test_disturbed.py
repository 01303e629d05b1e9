"""Tests of switchobs_core.sim.disturbed: the noise bound under a declared disturbance, in process."""

from __future__ import annotations

import math

import numpy as np
import pytest

import switchobs_core as so
from switchobs_core.model.scenarios import load_disturbance
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.sim.disturbed import bang_bang, disturbed_run, step_input

PER = [Cycle.from_ts(2.0, 0.6)]
X0 = np.array((0.0, 0.0, 0.2, 0.1, 3.0, 1.0, -0.1, 0.0, -2.0, 2.0, 0.1, 0.0))


def _observer(paper, table, dist):
    return so.SwitchedObserver(paper, table, "periodic", PER, x0=X0 + 0.2, e0=1.0, noise_max=3e-3,
                               disturbance=dist)


def test_bang_bang_accelerations_within_the_declared_bound_never_exceed_noise_bound(paper, paper_table):
    """Three bodies at 50 Hz, every velocity driven at +-0.2 m/s^2 with random switches, noise of
    1 mm clipped to 3 mm: with disturbance.max = 0.2 no sample is false, the consistency test never
    fires (every bound valid), and the bound stays within 100x of the error."""
    dist = load_disturbance("paper", paper, w_max=0.2)
    obs = _observer(paper, paper_table, dist)
    r = disturbed_run(paper, obs, PeriodicSchedule(PER[0]), 50.0, 10.0, X0, dist.B_w,
                      bang_bang(dist.w_max, 50.0, seed=4), noise_std=1e-3, noise_max=3e-3, seed=4)
    assert math.isnan(r.withdrawn_at), r.reason
    assert r.false_samples() == 0
    assert r.valid_fraction(4.0) == 1.0
    assert 1.0 < r.median_ratio(4.0) < 100.0


def test_an_undeclared_manoeuvre_is_caught_by_the_consistency_test(paper, paper_table):
    """One agent accelerating at 0.2 m/s^2 from 2 s on, no disturbance declared: the consistency
    test withdraws the bounds; with it declared, nothing is withdrawn and nothing false."""
    B_w = load_disturbance("paper", paper).B_w
    w = step_input(B_w.shape[1], 2, 0.2, 2.0)       # agent1's v_x
    sched = PeriodicSchedule(PER[0])
    bare = disturbed_run(paper, _observer(paper, paper_table, None), sched, 50.0, 10.0, X0, B_w, w,
                         noise_std=1e-3, noise_max=3e-3)
    assert 2.0 < bare.withdrawn_at < 10.0
    declared = load_disturbance("paper", paper, w_max=0.2)
    ok = disturbed_run(paper, _observer(paper, paper_table, declared), sched, 50.0, 10.0, X0, B_w, w,
                       noise_std=1e-3, noise_max=3e-3)
    assert math.isnan(ok.withdrawn_at) and ok.false_samples() == 0


def test_a_disturbance_needs_noise_max(paper, paper_table):
    with pytest.raises(so.InvalidArgument, match="noise_max"):
        so.SwitchedObserver(paper, paper_table, "periodic", PER, disturbance=load_disturbance("paper", paper, w_max=1))


def test_the_kalman_bound_under_a_constant_corner_is_within_20x(paper):
    """Kalman gains (Q_c from the disturbance), no initial error, noise-free samples, every velocity
    at +0.2 m/s^2: the bound holds the disturbance alone and stays within 20x of the error it
    causes (13x measured; the disturbance's second-order part is shaped too, so the correction's
    ``||I - K H||`` (about 200 balanced) does not multiply a ball)."""
    from switchobs_core.model.scenarios import load_noise

    dist = load_disturbance("paper", paper, w_max=0.2)
    table = so.kalman_table(paper, [so.design_kalman(paper, PER, 50.0, noise=load_noise("paper", paper,
                                                                                         disturbance=dist))])
    obs = so.SwitchedObserver(paper, table, "periodic", PER, x0=X0, e0=0.0, noise_max=0.0, disturbance=dist)
    r = disturbed_run(paper, obs, PeriodicSchedule(PER[0]), 50.0, 6.0, X0, dist.B_w, lambda t: np.full(6, 0.2))
    assert math.isnan(r.withdrawn_at) and r.false_samples() == 0
    assert r.error[-1] <= r.bound[-1] <= 20 * r.error[-1]
