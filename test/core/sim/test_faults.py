"""Faults through the consistency test and the recovery, in process (the paper's three bodies, 50 Hz,
the (2 s, 0.6) schedule, Gaussian noise of 1 cm clipped to noise_max = 3 cm): no published bound is
ever below the error, and the bounds come back from data after a bias, a gross fault, and with no e0."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.sim.faults import Fault, run_with_faults
from switchobs_core.table.gains import kalman_table

CYC = Cycle.from_ts(2.0, 0.6)
X0 = np.array([0, 0, 0.1, 0, 1, 2, 0.2, -0.1, -1, 3, 0, 0.2], float)
TARGET_ROWS = (2, 3)


@pytest.fixture(scope="module")
def setup(paper):
    nm = NoiseModel(meas_std=((0.01,) * 4,) * 2, Q_c=1e-4 * np.eye(12), P0=100 * np.eye(12))
    return paper, kalman_table(paper, [design_kalman(paper, CYC, 50.0, nm)]), PeriodicSchedule(CYC)


def _run(setup, xhat0, e0, faults, t_end):
    system, table, sched = setup
    return run_with_faults(system, table, sched, X0, xhat0, t_end, rate=50.0, noise_std=0.01, noise_max=0.03,
                           e0=e0, faults=faults)


def test_a_bias_on_the_target_poses_is_detected_and_the_bounds_come_back(setup):
    run = _run(setup, X0 + 0.05, 1.0, [Fault(4.5, 6.5, TARGET_ROWS, 0.05)], 11.0)
    assert run.false == 0
    assert run.withdrawals and 4.5 <= run.withdrawals[0][0] <= 4.6       # within a few samples
    assert "persistent bias" in run.withdrawals[0][1]
    assert run.recertified
    assert run.valid_fraction(6.5 + 2 * CYC.tau) >= 0.9


def test_a_gross_sensor_fault_withdraws_and_the_bound_is_recertified_a_cycle_after_it(setup):
    run = _run(setup, X0 + 0.05, 1.0, [Fault(4.5, 6.5, TARGET_ROWS, 1.0)], 11.0)
    assert run.false == 0
    assert run.withdrawals[0] == (4.5, "inconsistent sample")
    assert not run.valid[(run.t >= 4.5) & (run.t < 6.5)].any()     # nothing published during the fault
    assert run.first_bound_after(6.5) <= CYC.tau + 0.2
    assert run.valid_fraction(6.5 + 2 * CYC.tau) >= 0.9


def test_without_e0_the_first_bound_comes_after_one_cycle_and_holds(setup):
    off = np.array([3, -2, 0.5, 0.5, 2, 2, 0, 0, -3, 1, 0.3, 0], float)     # metres off
    run = _run(setup, X0 + off, None, [], 8.0)
    assert run.false == 0
    assert not run.valid[run.t < CYC.tau].any()
    assert run.first_bound_after(0.0) == pytest.approx(CYC.tau, abs=0.03)
    assert run.valid_fraction(3 * CYC.tau) >= 0.9


def test_fixed_gains_run_the_bias_test_only_with_a_covariance(paper, paper_table):
    """LMI gains: the innovations carry the estimate's transients (after the start, after each unseen
    stretch), many times the 1 mm noise. Without a covariance to say how large they are the bias
    test is off (it alarmed at the first sample on noise alone); with a noise model it runs, and
    neither run alarms or publishes a false bound."""
    from switchobs_core.model.noise import NoiseModel
    from switchobs_core.runtime.observer import SwitchedObserver
    from switchobs_core.runtime.recovery import Recovery

    sched = PeriodicSchedule(CYC)
    nm = NoiseModel.for_system(paper, measurement_std=1e-3)
    for noise in (None, nm):
        obs = SwitchedObserver(paper, paper_table, "periodic", [CYC], x0=X0, e0=1.0, noise_max=0.003, noise=noise)
        rec = Recovery(obs)
        assert (rec.bias is None) == (noise is None)
        assert ("no covariance" in rec.bias_off) == (noise is None)
        run = run_with_faults(paper, paper_table, sched, X0, X0 + 0.05, 6.0, rate=50.0, noise_std=0.001,
                              noise_max=0.003, e0=1.0, noise=noise)
        assert run.alarms == [] and run.withdrawals == [] and run.false == 0
