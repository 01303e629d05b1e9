"""Missing samples on a Kalman table's grid (:mod:`switchobs_core.runtime.families.gaps`): the
table stays on its grid, and the estimate and the covariance the observer reads (``P``, the prior
before a sample, whole and on a block) are the Kalman filter's.

The reference here is a dense filter written independently: exact discretisation by van Loan's
block exponential, the optimal gain of its own prior, the Joseph form. Tolerance: :data:`TOL` of
``sqrt(P_ii P_jj)`` on every entry, with the retire test off (``relock_rtol`` 1e-12), since a
retired deviation is left out of ``P`` on purpose (checked on its own below).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.table.gains import kalman_table

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
#: Covariances against the reference, relative to ``sqrt(P_ii P_jj)`` entry by entry; estimates
#: relative to the largest entry of the state.
TOL = 1e-8
#: Samples locked before the drops start (inside the start-up of the table).
K0 = 40
COLS = np.array([0, 3, 5, 9])


@pytest.fixture(scope="module")
def systems():
    out = {}
    for name, system in (("paper", paper_system()), ("agents2", camera_agents(2))):
        out[name] = (system, kalman_table(system, [design_kalman(system, CYC, RATE)]))
    return out


class Dense:
    """The reference: ``P <- F P F' + Q_d`` over any step, the Joseph form with the optimal gain."""

    def __init__(self, system, noise, x, P):
        self.A, self.Qc, self.n = np.asarray(system.A, float), noise.Q_c, system.n
        self.x, self.P, self._disc = x.copy(), P.copy(), {}

    def predict(self, dt: float) -> None:
        key = round(dt * 1e9)
        if key not in self._disc:
            n = self.n
            M = np.zeros((2 * n, 2 * n))
            M[:n, :n], M[:n, n:], M[n:, n:] = -self.A, self.Qc, self.A.T
            E = expm(M * dt)
            F = E[n:, n:].T
            Q = F @ E[:n, n:]
            self._disc[key] = (F, 0.5 * (Q + Q.T))
        F, Q = self._disc[key]
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q

    def correct(self, H, R, y) -> None:
        K = self.P @ H.T @ np.linalg.inv(H @ self.P @ H.T + R)
        self.x = self.x + K @ (y - H @ self.x)
        J = np.eye(self.n) - K @ H
        self.P = J @ self.P @ J.T + K @ R @ K.T
        self.P = 0.5 * (self.P + self.P.T)


def _close(got, want, what):
    d = np.sqrt(np.abs(np.diagonal(want)))
    err = np.abs(got - want) / np.maximum(np.outer(d, d), 1e-300)
    assert err.max() <= TOL, f"{what}: {err.max():.3g} of sqrt(P_ii P_jj)"


def _drive(system, table, stamps, *, rtol=1e-12, missing="table", before=None):
    """Feed ``stamps`` (the first K0 on the grid from 0) to an observer and, from sample K0 on,
    check it against :class:`Dense`; returns the observer.
    ``before(obs, t)``: called before each update."""
    obs = SwitchedObserver(system, table, "periodic", [CYC], x0=np.zeros(system.n), e0=1.0, relock_rtol=rtol)
    obs.gains.missing = missing
    noise, sched = obs.noise, PeriodicSchedule(CYC)
    truth = np.linspace(-1.0, 1.0, system.n)
    ref = None
    for t in stamps:
        c = sched.channel_at(t)
        H, R = system.C[c - 1], noise.R(c)
        y = H @ truth + 1e-3 * np.sin(np.arange(len(H)) + 7 * t)
        if ref is not None:
            ref.predict(t - obs.t)
            _close(obs.prior_covariance(t), ref.P, f"prior at {t}")
            _close(obs.prior_covariance(t, COLS), ref.P[np.ix_(COLS, COLS)], f"prior block at {t}")
        if before is not None:
            before(obs, t)
        x = obs.update(t, c, y)
        if ref is None:
            if t >= (K0 - 1) / RATE:
                ref = Dense(system, noise, x, obs.P)
            continue
        ref.correct(H, R, y)
        _close(obs.P, ref.P, f"P at {t}")
        np.testing.assert_allclose(x, ref.x, rtol=0, atol=TOL * max(1.0, np.abs(ref.x).max()))
    return obs


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(("paper", "agents2")),
       drops=st.lists(st.floats(0.0, 1.0), min_size=50, max_size=50), rate=st.sampled_from((0.1, 0.3, 0.6)))
def test_estimate_and_covariance_are_the_filters_for_any_drop_pattern(systems, name, drops, rate):
    """Any drop pattern (gaps overlapping, long runs of missing samples): ``P``, the prior and its
    block are the filter's, and the estimate too, all on the table (no departure)."""
    system, table = systems[name]
    ks = [*range(K0), *(K0 + j for j, u in enumerate(drops) if u >= rate), K0 + len(drops)]
    obs = _drive(system, table, [k / RATE for k in ks])
    g = obs.gains
    assert g.departures == 0 and g.gaps == sum(1 for a, b in zip(ks, ks[1:]) if b > a + 1)


def test_overlapping_gaps_stay_on_the_table(systems):
    """Single missing samples close together: every one is served from the table (no departure),
    the deviation of the earlier ones still alive at the later ones (checked against the reference)."""
    system, table = systems["paper"]
    missing = {K0 + 2, K0 + 4, K0 + 7, K0 + 9, K0 + 12}
    obs = _drive(system, table, [k / RATE for k in range(K0 + 30) if k not in missing])
    g = obs.gains
    assert g.departures == 0 and g.gaps == len(missing) and g.source == "table"
    assert g._gap.U is not None and g._gap.U.shape[1] >= 2


def test_a_deviation_too_far_departs(systems, monkeypatch):
    """A deviation past GAP_MAX times the stored prior departs: the recursion runs online from the
    real covariance (stored posterior plus the deviation), still the filter's."""
    from switchobs_core.runtime.families import gaps
    monkeypatch.setattr(gaps, "GAP_MAX", 1.5)
    system, table = systems["paper"]
    run = set(range(K0 + 3, K0 + 40))
    obs = _drive(system, table, [k / RATE for k in range(K0 + 60) if k not in run])
    why = obs.kalman_fallback
    assert obs.gains.departures == 1 and "missing samples" in why and "(more than 1.5)" in why


def test_a_gap_then_an_off_grid_stamp(systems):
    """A gap's deviation is still alive when a stamp off the grid departs: the recursion starts from
    the stored posterior plus the deviation, propagated over the off-grid step."""
    system, table = systems["agents2"]
    stamps = [k / RATE for k in range(K0 + 5) if k != K0 + 2] + [(K0 + 5.4) / RATE, (K0 + 6.4) / RATE]
    obs = _drive(system, table, stamps)
    assert obs.gains.gaps == 1 and obs.gains.departures == 1 and obs.gains_source == "online"


def test_the_deviation_retires_where_the_relock_test_accepts(systems):
    """With the default ``relock_rtol`` the deviation of one missing sample retires at the first
    sample whose real prior is within ``relock_rtol sqrt(S_ii S_jj)`` of the stored prior ``S``
    (row norms: a sufficient test, so there or later, never earlier); from there ``P`` is the
    stored posterior, the same doubles."""
    system, table = systems["paper"]
    obs = SwitchedObserver(system, table, "periodic", [CYC], x0=np.zeros(system.n), e0=1.0)
    g, kd, sched, rtol = obs.gains, obs.kalman, PeriodicSchedule(CYC), obs.relock_rtol
    ref, retired_at, accepted_at = None, None, None
    for k in range(400):
        t = k / RATE
        if k == K0 + 1:
            continue
        c = sched.channel_at(t)
        H, R = system.C[c - 1], obs.noise.R(c)
        if ref is not None:
            ref.predict(t - obs.t)
            S = g.kalman.startup[k].P_prior if k < len(kd.startup) else kd.periodic[k % kd.pattern.K].P_prior
            d = np.sqrt(np.diagonal(S))
            if accepted_at is None and np.all(np.abs(ref.P - S) <= rtol * np.outer(d, d)):
                accepted_at = k
        obs.update(t, c, H @ np.ones(system.n))
        if k == K0:
            ref = Dense(system, obs.noise, np.zeros(system.n), obs.P)
        elif ref is not None:
            ref.correct(H, R, np.zeros(len(H)))
        if retired_at is None and g.gaps_retired:
            retired_at = k
            np.testing.assert_array_equal(obs.P, kd.posterior(kd.phase_at(t)))
    assert g.gaps == 1 and g.departures == 0
    assert accepted_at is not None and retired_at is not None and retired_at >= accepted_at


def test_the_online_option_is_the_departure_path(systems):
    """``missing="online"``: a missing sample departs, and the run is the same doubles as a
    table that is made to depart (``depart``) just before that sample, the path every other
    departure takes."""
    system, table = systems["paper"]
    stamps = [k / RATE for k in range(K0 + 40) if k not in (K0 + 3, K0 + 20)]

    def run(missing, before):
        obs = SwitchedObserver(system, table, "periodic", [CYC], x0=np.zeros(system.n), e0=1.0)
        obs.gains.missing = missing
        sched, out = PeriodicSchedule(CYC), []
        for t in stamps:
            before(obs, t)
            c = sched.channel_at(t)
            out.append((obs.update(t, c, system.C[c - 1] @ np.ones(system.n)).copy(), obs.P))
        return obs, out

    def depart(obs, t):
        if min(abs(t - (K0 + 4) / RATE), abs(t - (K0 + 21) / RATE)) < 1e-12 and obs.gains_source == "table":
            obs.gains.depart("made to depart")

    a, xa = run("online", lambda obs, t: None)
    b, xb = run("table", depart)
    assert a.kalman_departures == b.kalman_departures >= 1 and a.kalman_relocks == b.kalman_relocks
    assert "missing" in a.kalman_fallback and b.gains.gaps == 0
    for (x1, P1), (x2, P2) in zip(xa, xb):
        assert np.array_equal(x1, x2) and np.array_equal(P1, P2)


def test_missing_is_checked(systems):
    system, table = systems["paper"]
    obs = SwitchedObserver(system, table, "periodic", [CYC])
    with pytest.raises(Exception, match="missing must be one of"):
        obs.gains.missing = "skip"


@pytest.mark.parametrize("name", ["paper", "agents2"])
def test_a_relock_in_the_sample_that_departs_counts_no_missing_sample(systems, name):
    """A switch one sample early departs; the grid moves to it (alignment) and, with a loose
    re-lock tolerance, the table re-locks in that same sample. Nothing was missing: no gap is
    counted (not the hundreds of samples between the grid's old and new positions taken as
    missing, with their deviation added to the covariance)."""
    system, table = systems[name]
    obs = SwitchedObserver(system, table, "periodic", [CYC], x0=np.zeros(system.n), e0=1.0, relock_rtol=0.9)
    sched = PeriodicSchedule(CYC)
    for k in range(365):
        t = k / RATE
        c = sched.channel_at(t + (1 / RATE if t > 6.6 else 0.0))
        obs.update(t, c, system.C[c - 1] @ np.ones(system.n))
    g = obs.gains
    assert g.departures >= 1 and g.relocks >= 1
    assert g.gaps == 0, g.gaps


def test_too_far_sees_past_a_state_of_zero_variance():
    """A state whose stored variance and deviation are both 0 (0 / 0) hides no other row past GAP_MAX."""
    from switchobs_core.runtime.families.gaps import GAP_MAX, GapDeviation
    gd = GapDeviation(None, lambda: None, 1e-3)
    gd.prior = lambda last_k, k: np.array([[0.0], [1.0]])
    assert gd.too_far(0, 2, np.array([0.0, 0.5 / GAP_MAX]))
    assert not gd.too_far(0, 2, np.array([0.0, 2.0 / GAP_MAX]))
    gd.prior = lambda last_k, k: np.array([[1e-3], [0.0]])
    assert gd.too_far(0, 2, np.array([0.0, 1.0]))       # a deviation where the table says none at all
