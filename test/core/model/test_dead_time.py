"""Switching dead time: blind intervals after each switch, in the schedule, both gain
families, the certificate, the simulator and the planner.

Oracles are computed here independently: the periodic Riccati recursion with the shared rows
while blind, the paper's eta_min condition with the closed-form kappa of its model, and the
cycle transition as a product of matrix exponentials.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.certificate import certify_cycle
from switchobs_core.cli import main
from switchobs_core.design.kalman import design_kalman, sample_pattern
from switchobs_core.design.lmi import Designer
from switchobs_core.design.plan import ScheduleCost, blind_samples, plan_schedule
from switchobs_core.exceptions import ScheduleError
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule, SequenceSchedule, common_rows, parse_schedule
from switchobs_core.paper import kappa_closed_form
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.sim.simulate import simulate
from switchobs_core.table.gains import GainTable, kalman_table


@pytest.fixture(scope="module")
def system():
    return paper_system()



# ---------------------------------------------------------------- schedule
def test_cycle_active_inactive_and_validation():
    c = Cycle.from_ts(2.0, 0.6, 0.2)
    assert c.h == (1.2, 0.8) and c.tau == 2.0 and c.s == 0.6
    assert c.active(1) == pytest.approx(1.0) and c.inactive(1) == pytest.approx(1.0)
    assert c.active(2) == pytest.approx(0.6) and c.inactive(2) == pytest.approx(1.4)
    assert c.label() == "(2 s, 0.6, dead 0.2 s)"
    assert c.to_dict() == {"tau": 2.0, "h": [1.2, 0.8], "dead_time": 0.2}
    assert Cycle.from_ts(2.0, 0.6).to_dict() == {"tau": 2.0, "h": [1.2, 0.8]}     # old tables keep their bytes
    assert not c.matches(Cycle.from_ts(2.0, 0.6)) and c.matches(Cycle.from_ts(2.0, 0.6, 0.2))
    with pytest.raises(ScheduleError, match="channel 2 nothing to see"):
        Cycle.from_ts(2.0, 0.6, 0.8)
    with pytest.raises(ScheduleError, match="dead time must be >= 0"):
        Cycle.from_ts(2.0, 0.6, -0.1)


def test_common_rows_of_the_camera_model(system):
    assert common_rows(system.C) == (0, 1)          # the camera's own position
    assert common_rows([np.eye(2), np.array([[1.0, 0.0], [0.0, 2.0]])]) == (0,)
    assert common_rows([np.eye(2), 2 * np.eye(2)]) == ()


@settings(max_examples=150, deadline=None)
@given(h1=st.floats(0.2, 3.0), h2=st.floats(0.2, 3.0), frac=st.floats(0.0, 0.95), t=st.floats(0.0, 50.0))
def test_blind_at_periodic_fast_path_equals_the_generic_rule(h1, h2, frac, t):
    d = frac * min(h1, h2)
    c = Cycle((h1, h2), d)
    per, seq = PeriodicSchedule(c), SequenceSchedule([c])
    ch, off = seq.slot_at(t)
    assert ch == seq.channel_at(t)          # the same arithmetic: equal at ties too
    # away from ties (a switching instant or a blind interval's end, which the periodic fast
    # path's modulo and the generic sum may round to either side) both rules agree
    edges = [k * c.tau + e for k in range(int(t // c.tau) - 1, int(t // c.tau) + 2)
             for e in (0.0, h1, d, h1 + d)]
    assume(min(abs(t - e) for e in edges) > 1e-7)
    assert per.blind_at(t) == seq.blind_at(t)
    assert seq.blind_at(t) == (d > 0 and off < d - 1e-9)


def test_parse_schedule_with_dead_time():
    s = parse_schedule("sequence:4,0.5;3,0.6", dead_time=0.25)
    assert [c.dead_time for c in s.cycles] == [0.25, 0.25]
    assert s.blind_at(0.1) and not s.blind_at(0.3) and s.blind_at(2.1) and s.blind_at(4.2) and not s.blind_at(4.3)
    with pytest.raises(ScheduleError, match="random"):
        parse_schedule("random:0.5,1", dead_time=0.1)


# ---------------------------------------------------------------- Kalman family
def riccati_oracle(system, rate, chans, blind, std=1e-3, q=1e-2, tol=1e-13, max_periods=5000):
    """Independent periodic Joseph-form recursion; blind samples measure the camera rows only."""
    A = np.asarray(system.A, float)
    n = A.shape[0]
    dt = 1.0 / rate
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -A, q * q * np.eye(n), A.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    Qd = (Qd + Qd.T) / 2
    P, prev = 100.0 * np.eye(n), None
    for _ in range(max_periods):
        priors = []
        for k, (c, b) in enumerate(zip(chans, blind)):
            if k > 0 or prev is not None:
                P = Phi @ P @ Phi.T + Qd
            priors.append(P.copy())
            H = np.asarray(system.C[c - 1], float)[[0, 1] if b else slice(None)]
            R = std ** 2 * np.eye(H.shape[0])
            K = np.linalg.solve(H @ P @ H.T + R, H @ P).T
            IKH = np.eye(n) - K @ H
            P = IKH @ P @ IKH.T + K @ R @ K.T
        if prev is not None and max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(priors, prev)) < tol:
            return priors
        prev = priors
    raise AssertionError("oracle did not converge")


@pytest.mark.parametrize("dead", [0.1, 0.3])
def test_kalman_blind_phases_equal_the_riccati_oracle(system, dead):
    rate = 20.0
    c = Cycle.from_ts(2.0, 0.6, dead)
    kd = design_kalman(system, c, rate)
    pat = kd.pattern
    kb = blind_samples(dead, rate)
    # the first k_d samples of each residence are blind, the rest see
    expect = tuple(j < kb for k in (24, 16) for j in range(k))
    assert pat.blind == expect and sum(pat.blind) == 2 * kb
    assert all(p.rows == (0, 1) for p, b in zip(kd.periodic, pat.blind) if b)
    assert all(p.rows is None and p.K.shape[1] == 4 for p, b in zip(kd.periodic, pat.blind) if not b)
    oracle = riccati_oracle(system, rate, pat.channels, pat.blind)
    for p, o in zip(kd.periodic, oracle):
        assert np.allclose(p.P_prior, o, rtol=1e-8, atol=1e-14)
    # the dead time costs accuracy: the mean prior trace grows with it
    base = design_kalman(system, Cycle.from_ts(2.0, 0.6), rate)
    tr = lambda d: np.mean([np.trace(p.P_prior) for p in d.periodic])
    assert tr(kd) > tr(base)


def test_kalman_table_round_trip_and_lookup(system, tmp_path):
    c = Cycle.from_ts(2.0, 0.6, 0.2)
    kd = design_kalman(system, c, 20.0)
    path = tmp_path / "k.json"
    kalman_table(system, [kd]).save(path)
    t = GainTable.load(path, system=system)
    kd2 = t.kalman_design([c], system)
    assert kd2.pattern.blind == kd.pattern.blind
    assert all(a.rows == b.rows and np.array_equal(a.K, b.K) for a, b in zip(kd.periodic, kd2.periodic))
    with pytest.raises(Exception, match="dead 0.2 s"):          # the cycle without its dead time is not it
        t.kalman_design([Cycle.from_ts(2.0, 0.6)], system)


def test_simulate_kalman_with_dead_time_stays_on_the_table(system):
    c = Cycle.from_ts(2.0, 0.6, 0.2)
    rate = 50.0
    table = kalman_table(system, [design_kalman(system, c, rate)])
    rng = np.random.default_rng(3)
    x0 = rng.standard_normal(system.n)
    res = simulate(system, table, PeriodicSchedule(c), x0, x0 + 0.1 * rng.standard_normal(system.n), 60.0,
                   rate=rate)
    assert int(np.sum(res.error_norm > res.exact_bound)) == 0
    assert res.error_norm[-1] < 1e-9
    # blind samples carry only the camera rows: 10 per residence (a sample at a switching instant
    # is in the new residence: the schedule's tie rule), and the last sample, at 60 s, opens one
    sch = PeriodicSchedule(c)
    blind = [len(y) == 2 for y in res.y]
    assert blind == [sch.blind_at(t) for t in res.t]
    assert sum(blind) == 30 * 2 * blind_samples(0.2, rate) + 1
    obs = SwitchedObserver(system, table, "periodic", [c], x0=np.zeros(system.n))
    for k in range(400):
        t = k / rate
        rows = (0, 1) if PeriodicSchedule(c).blind_at(t) else None
        y = np.zeros(2 if rows else 4)
        obs.update(t, PeriodicSchedule(c).channel_at(t), y, rows=rows)
    assert obs.kalman_departures == 0


# ---------------------------------------------------------------- LMI family
def test_lmi_eta_min_is_the_paper_condition_with_the_blind_interval(system):
    d, delta = 0.2, 0.99
    c = Cycle.from_ts(2.0, 0.6, d)
    emin = Designer(system, delta=delta).eta_min(c)
    for i, e in enumerate(emin):
        mu = system.decomposition(i + 1).mu
        h, u = c.h[i] - d, c.tau - c.h[i] + d
        g = e * h - mu * u - math.log(kappa_closed_form(e, i + 1) / delta)
        assert abs(g) < 1e-5, (i, g)
    assert all(a > b for a, b in zip(emin, Designer(system, delta=delta).eta_min(Cycle.from_ts(2.0, 0.6))))


def test_certificate_includes_the_open_loop_blind_intervals(system):
    d = 0.2
    c = Cycle.from_ts(2.0, 0.6, d)
    des = Designer(system).design(c)
    A = np.asarray(system.A, float)
    Phi = np.eye(system.n)
    for i, h in enumerate(c.h):
        L, C = np.asarray(des.L[i]), np.asarray(system.C[i])
        Phi = expm((A - L @ C) * (h - d)) @ expm(A * d) @ Phi
    cert = certify_cycle(system, des)
    assert np.allclose(cert.Phi, Phi, rtol=1e-10, atol=1e-12)
    assert cert.spectral_radius < 1
    f = [k * math.exp(m * (c.tau - h + d) - e * (h - d)) for k, m, e, h in zip(des.kappa, des.mu, des.eta, c.h)]
    assert np.allclose(cert.f, f, rtol=1e-12)


@pytest.mark.parametrize("rate", [None, 100.0])
def test_lmi_observer_applies_no_gain_while_blind(system, rate):
    d = 0.2
    c = Cycle.from_ts(2.0, 0.6, d)
    table = Designer(system).table([c])
    rng = np.random.default_rng(1)
    x0 = rng.standard_normal(system.n)
    res = simulate(system, table, PeriodicSchedule(c), x0, x0 + 0.1 * rng.standard_normal(system.n), 120.0,
                   rate=rate)
    assert int(np.sum(res.error_norm > res.exact_bound)) == 0
    assert res.error_norm[-1] < 1e-8 * max(1.0, np.abs(res.x[-1]).max())
    if rate is not None:        # consecutive blind samples: e_{k+1} = e^{A/f} e_k (open loop)
        F = expm(np.asarray(system.A, float) / rate)
        sch = PeriodicSchedule(c)
        ks = [k for k in range(1, 400) if sch.blind_at(res.t[k]) and sch.blind_at(res.t[k - 1])]
        assert len(ks) > 20
        for k in ks:
            e0, e1 = res.error[k - 1], res.error[k]
            assert np.allclose(e1, F @ e0, rtol=1e-7, atol=1e-12 * np.abs(res.x[k]).max())


# ---------------------------------------------------------------- plan
def test_plan_with_dead_time_beats_every_grid_point_and_is_interior(system):
    rate, d = 10.0, 0.2                           # k_d = 2 blind samples per residence
    J = ScheduleCost(system, rate, None, None, dead_time=d)
    assert J.k_dead == 2
    res = plan_schedule(system, rate, h_min=0.1, tau_max=2.0, cost=J, progress=False)
    assert res.cycle.dead_time == d and min(res.counts) >= 3
    grid = [k for k in itertools.product(range(3, 21), repeat=2) if sum(k) <= 20]
    costs = {k: J(k) for k in grid}
    assert res.cost <= min(costs.values()) * (1 + 1e-9)
    # checked independently for the optimum and two neighbours
    for k in [res.counts, (res.counts[0] + 1, res.counts[1]), (3, 3)]:
        chans = [1] * k[0] + [2] * k[1]
        blind = [j < 2 for j in range(k[0])] + [j < 2 for j in range(k[1])]
        o = riccati_oracle(system, rate, chans, blind)
        assert J(k) == pytest.approx(np.mean([np.trace(P) for P in o]), rel=1e-7)
    # without a dead time the fastest switching allowed (one sample each) wins; with one that
    # schedule is not admissible (a residence no longer than the dead time)
    free = plan_schedule(system, rate, h_min=0.1, tau_max=2.0, progress=False)
    assert free.counts == (1, 1) and math.isinf(J(free.counts))


def test_cli_design_simulate_plan_take_dead_time(system, tmp_path, capsys):
    out = tmp_path / "g.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--dead-time", "0.2", "-o", str(out)]) == 0
    assert main(["simulate", "paper", "--table", str(out), "--schedule", "periodic:2,0.6", "--dead-time", "0.2",
                 "--rate", "50", "--t-end", "10", "--json"]) == 0
    assert main(["design", "paper", "--cycle", "2,0.6", "--dead-time", "0.9", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--dead-time 0.9" in err and "nothing to see" in err and err.count("\n") == 1
    assert main(["simulate", "paper", "--table", str(out), "--schedule", "periodic:2,0.6", "--t-end", "1"]) == 2
    assert "dead 0.2 s" in capsys.readouterr().err       # the table's cycle has a dead time, the schedule none
    pat = sample_pattern(Cycle.from_ts(2.0, 0.6, 0.2), 50.0)
    assert sum(pat.blind) == 2 * blind_samples(0.2, 50.0) == 20
