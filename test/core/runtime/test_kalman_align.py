"""A Kalman table whose first sample falls anywhere in the sensors' cycle (a node started after the
camera): it departs at once, moves its grid to the schedule at the first switch it sees, and
re-locks within a few cycles; from then on its gains are the table's (lookup cost) and its
covariance is an online Kalman filter's (the family ``kalman-online``, same samples) to 1 % of its
largest entry, its estimate the filter's to 1 % of the error's scale. Without the alignment it ran
the recursion online for the rest of the run (paper system: every sample of 40 s)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.table.gains import kalman_table

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
SECONDS = 12.0


@pytest.fixture(scope="module")
def ktable(paper):
    return kalman_table(paper, [design_kalman(paper, CYC, RATE)])


@settings(max_examples=8, deadline=None)
@given(offset=st.integers(1, 99), seed=st.integers(0, 2**31 - 1))
def test_a_table_started_mid_cycle_relocks_and_matches_the_filter(paper, ktable, offset, seed):
    table = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    online = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0, family="kalman-online",
                              noise=table.noise)
    sched, F, rng = PeriodicSchedule(CYC), expm(paper.A / RATE), np.random.default_rng(seed)
    x = rng.normal(size=paper.n)
    locked_late = []
    for k in range(offset, offset + int(SECONDS * RATE)):
        t = k / RATE
        x = F @ x
        c = sched.channel_at(t)
        y = paper.C[c - 1] @ x + rng.normal(scale=1e-3, size=4)
        table.update(t - offset / RATE, c, y)
        online.update(t - offset / RATE, c, y)
        if t - offset / RATE >= SECONDS / 2:
            locked_late.append(table._gains.source == "table")
    g = table._gains
    assert g.departures >= 1 and g.alignments >= 1 and g.relocks >= 1
    assert all(locked_late), "locked for the second half of the run"
    P, Q = table.P, online.P
    assert np.abs(P - Q).max() <= 1e-2 * np.abs(Q).max()
    err = np.linalg.norm(online.x_hat - x)
    assert np.linalg.norm(table.x_hat - online.x_hat) <= 1e-2 * max(err, 1e-3)


def test_a_table_started_at_the_cycle_start_never_moves(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    sched, x = PeriodicSchedule(CYC), np.ones(paper.n)
    for k in range(int(SECONDS * RATE)):
        t = k / RATE
        obs.update(t, sched.channel_at(t), paper.C[sched.channel_at(t) - 1] @ x)
    assert obs._gains.departures == 0 and obs._gains.alignments == 0 and obs._gains.source == "table"
