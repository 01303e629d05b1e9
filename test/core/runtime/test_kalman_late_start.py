"""The Kalman table when the first sample comes after the observer's t0: its published covariance is
the exact recursion's from ``P0`` at t0 (an independent Joseph-form filter written here), the
normalised error of a Monte Carlo ensemble is in the chi-square band, and the table re-locks and
serves the samples once the recursion meets its stored priors; ties at switching instants (this
schedule puts samples on them) do not leave it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

import switchobs_core as so
from switchobs_core.numerics.propagation import van_loan

RATE = 50.0
CYC = so.Cycle.from_ts(2.0, 0.6)        # switching instants at 1.2 s and 2 s: samples on both


@pytest.fixture(scope="module")
def setup():
    paper = so.paper_system()
    table = so.kalman_table(paper, [so.design_kalman(paper, CYC, RATE)])
    return paper, table, table.kalman_design([CYC], paper).noise


def _joseph(P, H, R):
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    IKH = np.eye(P.shape[0]) - K @ H
    return IKH @ P @ IKH.T + K @ R @ K.T


def test_late_first_sample_publishes_the_exact_covariance(setup):
    """First sample 5 s after t0 (the schedule starts there): P0 at t0 propagated over 5 s, then
    the recursion; the published P within 1 % in trace and 5 % per variance of the reference at
    every sample (measured: 0.04 % and 0.06 %; the table served P0 itself there, 11x too small in
    trace); one departure, one re-lock, the table serves every sample of the second half."""
    paper, table, noise = setup
    late = 5.0
    obs = so.SwitchedObserver(paper, table, "periodic", [CYC], t0=0.0, rounding_bound=False)
    sch = so.PeriodicSchedule(CYC, t0=late)
    P, tp = noise.P0.copy(), 0.0
    N = int(40 * RATE)
    served = 0
    for k in range(N):
        t = late + k / RATE
        ch = sch.channel_at(t)
        F, Qd = van_loan(paper.A, noise.Q_c, t - tp)
        tp = t
        P = _joseph(F @ P @ F.T + Qd, paper.C[ch - 1], noise.R(ch, None))
        obs.update(t, ch, np.zeros(paper.C[ch - 1].shape[0]))
        Po = obs.P
        assert abs(np.trace(Po) - np.trace(P)) <= 0.01 * np.trace(P), (k, np.trace(Po), np.trace(P))
        assert np.all(np.abs(np.diag(Po) - np.diag(P)) <= 0.05 * np.diag(P)), k
        served += k >= N // 2 and obs.gains_source == "table"
    assert "first sample comes 5 s after t0" in obs.kalman_fallback
    assert obs.kalman_departures == 1 and obs.kalman_relocks == 1
    assert served == N - N // 2


def test_late_first_sample_nees_in_band(setup):
    """200 Monte Carlo runs, first sample 1 s after t0 (x0 ~ N(0, P0) at t0, the declared process
    and measurement noise): the ensemble's mean NEES lies in the chi-square 95 % band at all but a
    few percent of the samples (expected 5 %)."""
    paper, table, noise = setup
    runs, n, late, seconds = 200, paper.n, 1.0, 6.0
    rng = np.random.default_rng(21)
    x = np.linalg.cholesky(noise.P0) @ rng.standard_normal((n, runs))
    F, Qd = van_loan(paper.A, noise.Q_c, late)
    x = F @ x + np.linalg.cholesky(Qd) @ rng.standard_normal((n, runs))
    Ff, Qf = van_loan(paper.A, noise.Q_c, 1 / RATE)
    Lf = np.linalg.cholesky(Qf)
    observers = [so.SwitchedObserver(paper, table, "periodic", [CYC], t0=0.0, rounding_bound=False)
                 for _ in range(runs)]
    sch = so.PeriodicSchedule(CYC, t0=late)
    lo, hi = chi2.ppf(0.025, runs * n) / runs, chi2.ppf(0.975, runs * n) / runs
    outside = steps = 0
    for k in range(int(seconds * RATE)):
        t = late + k / RATE
        if k:
            x = Ff @ x + Lf @ rng.standard_normal((n, runs))
        ch = sch.channel_at(t)
        H = paper.C[ch - 1]
        y = H @ x + np.sqrt(np.diag(noise.R(ch, None)))[:, None] * rng.standard_normal((H.shape[0], runs))
        err = np.empty((n, runs))
        for j, o in enumerate(observers):
            err[:, j] = o.update(t, ch, y[:, j]) - x[:, j]
        Pi = np.linalg.inv(observers[0].P)
        nees = float(np.mean(np.einsum("ij,ik,kj->j", err, Pi, err)))
        steps += 1
        outside += not lo <= nees <= hi
    assert outside <= 0.1 * steps, (outside, steps)
    assert all(o.kalman_relocks == 1 for o in observers[:3])
