"""The Kalman gain families in the observer: table lookup equals the online Riccati recursion,
the exact bound holds with Kalman gains, off-schedule samples fall back to the online
recursion, tables round-trip (and version-1 tables still load), covariances are honest."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.stats import chi2

from switchobs_core.design.kalman import design_kalman
from switchobs_core.design.lmi import design_table
from switchobs_core.exceptions import GainTableError, InvalidArgument
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule, SequenceSchedule
from switchobs_core.model.system import LTISystem
from switchobs_core.numerics.propagation import van_loan
from switchobs_core.runtime.observer import NOT_APPLICABLE, SwitchedObserver
from switchobs_core.table.gains import GainTable, kalman_table

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
SEQ = [Cycle.from_ts(4, 0.5), Cycle.from_ts(3, 0.6), Cycle.from_ts(3, 0.6), Cycle.from_ts(2, 0.4)]
X0 = np.array([0, 0, 0.1, 0, 1, 2, 0.2, -0.1, -1, 3, 0, 0.2], float)


@pytest.fixture(scope="module")
def paper():
    return paper_system()


@pytest.fixture(scope="module")
def ktable(paper):
    """A kalman table (periodic (2 s, 0.6) and the paper's sequence at 50 Hz), through its JSON text."""
    t = kalman_table(paper, [design_kalman(paper, CYC, RATE), design_kalman(paper, SEQ, RATE)])
    return GainTable.from_json(t.to_json(), system=paper)


def _noisy(system, schedule, rate, seconds, *, seed):
    """(t, channel, y, x) of the exact plant from X0 at ``rate``, 1 mm measurement noise (seeded)."""
    F = expm(system.A / rate)
    rng = np.random.default_rng(seed)
    x = X0.copy()
    for k in range(int(seconds * rate)):
        t = k / rate
        if k:
            x = F @ x
        ch = schedule.channel_at(t)
        yield t, ch, system.C[ch - 1] @ x + rng.normal(scale=1e-3, size=system.C[ch - 1].shape[0]), x


def _run(system, observers, schedule, seconds, *, x0=X0, skip=()):
    """Feed noise-free samples of the exact plant at RATE to every observer; errors per observer."""
    F = expm(system.A / RATE)
    x = x0.copy()
    errs = [[] for _ in observers]
    for k in range(int(seconds * RATE) + 1):
        t = k / RATE
        if k:
            x = F @ x
        ch = schedule.channel_at(t)
        y = system.C[ch - 1] @ x
        for o, e in zip(observers, errs):
            if k in skip:
                continue
            o.update(t, ch, y)
            e.append((np.linalg.norm(o.x_hat - x), o.envelope().exact_bound))
    return [np.array(e) for e in errs]


@pytest.mark.parametrize("mode,cycles", [("periodic", [CYC]), ("sequence", SEQ)])
def test_table_lookup_equals_online_riccati(paper, mode, cycles):
    """At 48 Hz no sample falls on a switching instant (1.2 * 48 is not whole), so the table's
    sample pattern is exactly the stream's: the looked-up gains are the online recursion's, and
    so are the estimates and covariances, through the start-up and several periods (noisy data,
    so the estimates are compared at the scale of their errors)."""
    rate = 48.0
    table = kalman_table(paper, [design_kalman(paper, cycles, rate)])
    table_obs = SwitchedObserver(paper, table, mode, cycles, e0=10.0)
    online = SwitchedObserver(paper, table, mode, cycles, e0=10.0, family="kalman-online")
    assert (table_obs.family, online.family) == ("kalman", "kalman-online")
    schedule = PeriodicSchedule(CYC) if mode == "periodic" else SequenceSchedule(SEQ)
    seconds = 20.0 if mode == "periodic" else 30.0        # start-up and several periods
    worst_x = worst_P = 0.0
    for t, ch, y, x in _noisy(paper, schedule, rate, seconds, seed=3):
        a, b = table_obs.update(t, ch, y), online.update(t, ch, y)
        worst_x = max(worst_x, np.linalg.norm(a - b) / np.linalg.norm(b - x))
        Pa, Pb = table_obs.P, online.P
        worst_P = max(worst_P, np.abs(Pa - Pb).max() / np.abs(Pb).max())
    assert worst_x < 1e-6 and worst_P < 1e-7, (worst_x, worst_P)
    assert table_obs.kalman_fallback == ""


def test_tie_samples_follow_the_tables_rule(paper, ktable):
    """At 50 Hz the sample 1.2 s into each cycle lies on a switching instant. The schedule puts it
    on the new channel whatever the float arithmetic of its stamp (the tie rule of
    :mod:`switchobs_core.model.schedule`), and so did the design: the table serves every sample and
    equals the online filter. A stream that puts the tie on the old channel instead leaves the
    table there, runs the recursion online from the stored prior and re-locks once its covariance
    is back within relock_rtol: the estimate is the online filter's to a fraction of a percent."""
    sched = PeriodicSchedule(CYC)
    for old_channel in (False, True):
        table_obs = SwitchedObserver(paper, ktable, "periodic", [CYC])
        online = SwitchedObserver(paper, ktable, "periodic", [CYC], family="kalman-online")
        sq = np.zeros(2)
        served = ties = 0
        for t, ch, y, x in _noisy(paper, sched, RATE, 30.0, seed=4):
            if sched.channel_at(t - 1e-6) != ch:       # a switching instant
                ties += 1
                if old_channel and t > 0:
                    ch = sched.channel_at(t - 1e-6)
                    y = paper.C[ch - 1] @ x
            a, b = table_obs.update(t, ch, y), online.update(t, ch, y)
            served += table_obs.gains_source == "table"
            if t >= 15.0:
                sq += (np.sum((a - x) ** 2), np.sum((b - x) ** 2))
        assert ties >= 25
        if old_channel:
            assert table_obs.kalman_departures >= 1
            assert table_obs.kalman_relocks >= table_obs.kalman_departures - 1
            assert sq[0] <= 1.005 * sq[1], np.sqrt(sq[0] / sq[1])
        else:
            assert table_obs.kalman_departures == 0 and served == int(30.0 * RATE)
            assert sq[0] == pytest.approx(sq[1], rel=1e-6)


def test_exact_bound_holds_with_kalman_gains(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], e0=float(np.linalg.norm(X0)) * 1.0000001)
    (err,) = _run(paper, [obs], PeriodicSchedule(CYC), 20.0)
    assert np.all(err[:, 0] <= err[:, 1] * (1 + 1e-9) + 1e-12)
    # and it is informative: the noise-free error falls by orders of magnitude within 10 s
    assert err[int(10 * RATE), 0] < 1e-6 * err[0, 0] + 1e-9
    env = obs.envelope()
    assert np.all(env.z == NOT_APPLICABLE) and env.paper_bound == NOT_APPLICABLE


def test_off_schedule_sample_falls_back_to_online(paper, ktable):
    """An observer that starts 0.5 s into the schedule takes its first sample as phase 0, so
    the channel changes arrive where its table has none: it runs the recursion online (the
    Kalman filter for what really happens), converges, and its exact bound holds."""
    late = SwitchedObserver(paper, ktable, "periodic", [CYC], e0=10.0)
    (err,) = _run(paper, [late], PeriodicSchedule(CYC), 20.0, skip=range(25))
    assert late.kalman_departures >= 1
    assert "running the Riccati recursion online" in late.kalman_fallback
    assert err[-1, 0] < 1e-8 * err[0, 0]
    assert np.all(err[:, 0] <= err[:, 1] * (1 + 1e-9) + 1e-12)


def test_version_1_lmi_table_still_loads(paper):
    table = design_table(paper, cycles=[CYC], delta=0.99, progress=False)
    data = json.loads(table.to_json())
    data.pop("payload_sha256")
    data.pop("family")
    data.pop("kalman")
    data["format_version"] = 1
    data["payload_sha256"] = GainTable._digest(data)
    old = GainTable.from_json(json.dumps(data), system=paper)
    assert old.family == "lmi" and old.lookup(CYC).eta == table.lookup(CYC).eta
    with pytest.raises(InvalidArgument, match="LMI gain table"):
        SwitchedObserver(paper, kalman_table(paper, [design_kalman(paper, CYC, RATE)]), "periodic", [CYC],
                         family="lmi")


def test_table_for_another_schedule_is_refused(paper, ktable):
    with pytest.raises(GainTableError, match="no Kalman design for the cycle sequence"):
        SwitchedObserver(paper, ktable, "periodic", [Cycle.from_ts(2.0, 0.5)])


def test_noise_model_and_rate_are_part_of_the_checksum(paper):
    a = kalman_table(paper, [design_kalman(paper, CYC, RATE)]).to_json()
    b = kalman_table(paper, [design_kalman(paper, CYC, RATE, NoiseModel.for_system(paper, measurement_std=1e-2))])
    c = kalman_table(paper, [design_kalman(paper, CYC, 25.0)])
    digests = {json.loads(t)["payload_sha256"] for t in (a, b.to_json(), c.to_json())}
    assert len(digests) == 3


def test_lmi_covariance_is_consistent(paper):
    """LMI gains with a noise model: the propagated covariance P matches the Monte Carlo spread
    of the error (average NEES in the chi-square 95 % band), process and measurement noise on."""
    table = design_table(paper, cycles=[CYC], delta=0.99, progress=False)
    noise = NoiseModel.for_system(paper, measurement_std=1e-2, process_std=0.05, P0=0.25)
    F, Qd = van_loan(paper.A, noise.Q_c, 1 / RATE)
    Lq = np.linalg.cholesky(Qd + 1e-18 * np.eye(12))
    runs, steps = 60, int(6 * RATE)
    nees = np.zeros(runs)
    sched = PeriodicSchedule(CYC)
    for r in range(runs):
        rng = np.random.default_rng(r)
        obs = SwitchedObserver(paper, table, "periodic", [CYC], noise=noise)
        x = rng.normal(scale=0.5, size=12)           # x_hat(0) = 0, so x_tilde(0) ~ N(0, P0)
        for k in range(steps):
            t = k / RATE
            if k:
                x = F @ x + Lq @ rng.normal(size=12)
            ch = sched.channel_at(t)
            y = paper.C[ch - 1] @ x + rng.normal(scale=1e-2, size=4)
            obs.update(t, ch, y)
        e = obs.x_hat - x
        nees[r] = e @ np.linalg.solve(obs.P, e)
    lo, hi = chi2.ppf([0.025, 0.975], runs * 12) / runs
    assert lo <= nees.mean() <= hi, (nees.mean(), lo, hi)


@pytest.mark.parametrize("family", ["lmi", "kalman"])
def test_set_estimate_sets_entries_and_covariance(paper, family):
    """set_estimate (the node's ~/set_state): the entries take the given values at t, the rest is
    the propagated estimate; P gets the given variance with the entry decoupled; a Kalman table
    goes online from there and the filter keeps converging."""
    import switchobs_core as so

    cyc = [so.Cycle.from_ts(2.0, 0.6)]
    table = (so.design_table(paper, cycles=cyc, delta=0.99, progress=False) if family == "lmi"
             else so.kalman_table(paper, [so.design_kalman(paper, cyc, 100.0)]))
    noise = None if family == "kalman" else so.default_noise(paper)
    obs = so.SwitchedObserver(paper, table, "periodic", cyc, noise=noise)
    plant = so.Plant(paper, np.array([0, 0, 0.2, 0.1, 3, 1, -0.1, 0, -2, 2, 0.1, 0], float))
    sched = so.PeriodicSchedule(cyc[0])
    for k in range(300):
        t = k / 100
        c = sched.channel_at(t)
        plant.advance(t)
        obs.update(t, c, plant.measure(c))
    expected = obs.predict(3.005, hold=True)
    obs.set_estimate(3.005, {4: 7.0}, {4: 0.25})
    assert obs.t == 3.005 and obs.x_hat[4] == 7.0
    np.testing.assert_allclose(np.delete(obs.x_hat, 4), np.delete(expected, 4), rtol=1e-12, atol=1e-12)
    P = obs.P
    assert P[4, 4] == 0.25 and not np.delete(P[4], 4).any()
    with pytest.raises(InvalidArgument):
        obs.set_estimate(1.0, {0: 1.0})          # the past
    with pytest.raises(InvalidArgument):
        obs.set_estimate(3.01, {12: 1.0})        # no such state
    for k in range(301, 1500):                    # the filter pulls the wrong entry back
        t = k / 100
        c = sched.channel_at(t)
        plant.advance(t)
        obs.update(t, c, plant.measure(c))
    assert abs(obs.x_hat[4] - plant.x[4]) < 1e-3


def _input_system(paper):
    """The paper's A and C with a 2-column input."""
    B = np.zeros((paper.n, 2))
    B[2, 0] = B[3, 1] = 1.0
    return LTISystem(paper.A, B, paper.C, name="paper_input")


@pytest.mark.parametrize("family", ["kalman", "kalman-online"])
@pytest.mark.parametrize("dead", [0.0, 0.2])
def test_an_input_acts_from_its_sample_on(paper, family, dead):
    """``u`` given with a sample is held from that sample on: the estimate at the sample is the same
    double with and without it, on the first sample after a reset at a later time and on every
    sample of a dead-time table's blind phases (where the table takes the step with its correction)."""
    system = _input_system(paper)
    cyc = Cycle.from_ts(2.0, 0.6, dead)
    table = kalman_table(system, [design_kalman(system, cyc, 40.0)])
    sched = PeriodicSchedule(cyc)
    blind = [k for k in range(1, 160) if (k / 40.0) % 2.0 < dead - 1e-9 or 1.2 <= (k / 40.0) % 2.0 < 1.2 + dead - 1e-9]
    checks = [1] + blind[:6]
    for k in checks:
        xs = []
        for u in (None, [5.0, -3.0]):
            obs = SwitchedObserver(system, table, cycles=[cyc], family=family, x0=X0)
            obs.reset(X0, 0.0)
            for j in range(1, k + 1):
                t = j / 40.0
                ch = sched.channel_at(t)
                rows = (0, 1) if j in blind else None
                C = np.asarray(system.C[ch - 1])
                y = (C if rows is None else C[list(rows)]) @ (expm(np.asarray(system.A) * t) @ X0)
                x = obs.update(t, ch, y, u=u if j == k else None, rows=rows)
            xs.append(x.copy())
        assert np.array_equal(xs[0], xs[1]), (family, dead, k)
