"""The exact bound where a step's residual squares below the smallest double
(:mod:`switchobs_core.numerics.rounding`: the added ball of radius rho is kept, rho^2 rounded up to at
least the smallest subnormal). A constant state of size 1e-147 observed with a small Kalman gain
(K ~ 1e-6): the estimate's rounding leaves it stuck 1e5 ulps from the truth (K (y - x_hat) is below
half an ulp), and each step's residual rho (~9e-163) squares to 0 in double. The bound must stay
above that error at every sample (the error is exact: two doubles within a factor 2)."""

from __future__ import annotations

import math

import numpy as np

import switchobs_core as so


def test_bound_covers_a_state_whose_residual_squares_below_the_smallest_double():
    A = np.array([[0.0]])
    system = so.LTISystem(A, None, [np.array([[1.0]]), np.array([[1.0]])], name="constant")
    cycle = so.Cycle((0.2, 0.2))
    noise = so.NoiseModel([[1.0], [1.0]], np.array([[5e-11]]), np.array([[1e-6]]))
    table = so.kalman_table(system, [so.design_kalman(system, cycle, 50.0, noise)])
    sched = so.PeriodicSchedule(cycle)
    x = 1e-147
    xh0 = x - 100_000 * math.ulp(x)
    obs = so.SwitchedObserver(system, table, "periodic", [cycle], x0=[xh0], e0=(x - xh0) * (1 + 1e-9))
    for k in range(100):
        t = k / 50.0
        err = abs(float(obs.update(t, sched.channel_at(t), np.array([x]))[0]) - x)
        assert err <= obs.envelope().exact_bound, (k, err, obs.envelope().exact_bound)
