"""The prior covariance a locked Kalman table has stored: what the chi-square gate and the bias test
read before a sample (``SwitchedObserver.prior_covariance``) is the next phase's stored prior while
the table is locked, equal to the last posterior propagated over the step (within the design's
rounding), and the propagated one wherever the table is not (a missing sample, a step off the
grid, after a departure)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.table.gains import kalman_table

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
#: The stored prior against the posterior propagated in double, relative to its largest entry.
RTOL = 1e-9


@pytest.fixture(scope="module")
def ktable(paper):
    return kalman_table(paper, [design_kalman(paper, CYC, RATE)])


def _propagated(obs, t):
    dt = t - obs.t
    return obs._gains.predict_covariance(obs.P, obs._cache.step(obs._held()[0], dt), dt)


def test_the_stored_prior_is_the_propagated_posterior_while_locked(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    sched, F, x = PeriodicSchedule(CYC), expm(paper.A / RATE), np.ones(paper.n)
    stored = 0
    for k in range(int(12 * RATE) + 1):         # start-up and periodic phases
        t = k / RATE
        if k:
            x = F @ x
            S = obs._gains.stored_prior(t, t - obs.t)
            assert S is not None
            stored += 1
            P = _propagated(obs, t)
            np.testing.assert_allclose(obs.prior_covariance(t), P, rtol=0, atol=RTOL * np.abs(P).max())
        c = sched.channel_at(t)
        obs.update(t, c, paper.C[c - 1] @ x)
    assert obs._gains.source == "table" and stored == int(12 * RATE)


def test_off_the_grid_or_after_a_departure_the_prior_is_propagated(paper, ktable):
    """With ``missing="online"`` a missing sample is a departure like a stamp off the grid."""
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    obs.gains.missing = "online"
    sched, x = PeriodicSchedule(CYC), np.ones(paper.n)
    for k in range(50):
        t = k / RATE
        obs.update(t, sched.channel_at(t), paper.C[sched.channel_at(t) - 1] @ x)
    t = 50 / RATE
    assert obs._gains.stored_prior(t + 0.3 / RATE, t + 0.3 / RATE - obs.t) is None     # off the grid
    t_skip = 51 / RATE                                                                    # sample 50 missing
    assert obs._gains.stored_prior(t_skip, t_skip - obs.t) is None
    P = _propagated(obs, t_skip)
    np.testing.assert_array_equal(obs.prior_covariance(t_skip), P)
    obs.update(t_skip, sched.channel_at(t_skip), paper.C[sched.channel_at(t_skip) - 1] @ x)
    assert obs._gains.source == "online"                                                  # departed
    t = 52 / RATE
    assert obs._gains.stored_prior(t, t - obs.t) is None
    np.testing.assert_array_equal(obs.prior_covariance(t), _propagated(obs, t))


def test_after_a_missing_sample_the_prior_is_the_propagated_posterior(paper, ktable):
    """The default ``missing="table"``: the prior over a missing sample is the stored prior plus the
    gap's deviation, the last posterior propagated over two steps (within the design's rounding),
    whole and on a block; the table stays locked."""
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    sched, x = PeriodicSchedule(CYC), np.ones(paper.n)
    for k in (*range(50), 51, 53, 56):          # samples 50, 52, 54 and 55 missing
        t = k / RATE
        if k > 50:
            P = _propagated(obs, t)
            S = obs._gains.stored_prior(t, t - obs.t)
            assert S is not None
            np.testing.assert_allclose(S, P, rtol=0, atol=RTOL * np.abs(P).max())
            cols = np.array([0, 3, 7])
            np.testing.assert_allclose(obs.prior_covariance(t, cols), P[np.ix_(cols, cols)], rtol=0,
                                       atol=RTOL * np.abs(P).max())
        obs.update(t, sched.channel_at(t), paper.C[sched.channel_at(t) - 1] @ x)
    assert obs._gains.source == "table" and obs.gains.departures == 0 and obs.gains.gaps == 3


def test_the_bias_tests_block_is_the_priors_block_and_unpacks_nothing(paper, ktable, tmp_path):
    """``prior_covariance(t, cols)``: the block of ``prior_covariance(t)`` on ``cols``, the same
    doubles, locked (from a version-4 file's packed rows: the phase keeps its verified packed row
    and makes no n x n matrix) and off the grid (the propagated prior)."""
    from switchobs_core.table.gains import GainTable
    from switchobs_core.table.rows import LazyRow

    loaded = GainTable.load(ktable.save(tmp_path / "k.npz"), system=paper)
    kd = loaded.kalman_design([CYC], paper)
    assert all(isinstance(ph.P_stored, LazyRow) for ph in kd.startup[:5])
    obs = SwitchedObserver(paper, loaded, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    ref = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    sched, F, x = PeriodicSchedule(CYC), expm(paper.A / RATE), np.ones(paper.n)
    cols = np.array([0, 1, 4, 5])
    for k in range(int(3 * RATE)):
        t = k / RATE
        if k:
            x = F @ x
            block = obs.prior_covariance(t, cols)
            ph = kd.startup[k] if k < len(kd.startup) else kd.periodic[k % len(kd.periodic)]
            assert ph.P_stored.ndim == 1                      # verified, kept packed, not unpacked
            np.testing.assert_array_equal(block, ref.prior_covariance(t)[np.ix_(cols, cols)])
        c = sched.channel_at(t)
        obs.update(t, c, paper.C[c - 1] @ x)
        ref.update(t, c, paper.C[c - 1] @ x)
    full = obs.prior_covariance(obs.t + 1 / RATE)               # the matrix, unpacked on demand
    np.testing.assert_array_equal(full[np.ix_(cols, cols)], obs.prior_covariance(obs.t + 1 / RATE, cols))
    t_off = obs.t + 1.3 / RATE                                  # off the grid: the propagated prior's block
    assert obs._gains.stored_prior(t_off, t_off - obs.t) is None
    np.testing.assert_array_equal(obs.prior_covariance(t_off, cols), obs.prior_covariance(t_off)[np.ix_(cols, cols)])
    assert obs.prior_covariance(float("nan"), cols) is None
