"""``switchobs plan``: the schedule optimiser against an independent brute force.

The oracle below is written here, not taken from plan.py / riccati.py: exact discretisation by
van Loan's block exponential, a plain Joseph-form Riccati recursion iterated period by period
until the priors repeat, and the time average of tr(W P^-_k) over one period.
"""

from __future__ import annotations

import itertools
import json
import shlex

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.cli import build_parser, main
from switchobs_core.design.plan import ScheduleCost, neighbours, parse_weights, plan_schedule
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle

RATE = 5.0
H_MIN = 0.2     # one sample
TAU_MAX = 2.0   # at most 10 samples per period


def oracle_cost(system, rate, counts, meas_std=1e-3, q=1e-2, w=None, tol=1e-13, max_periods=20000):
    """Independent periodic Joseph-form Riccati: mean over one period of tr(W P^-_k)."""
    A = np.asarray(system.A, float)
    n = A.shape[0]
    dt = 1.0 / rate
    Qc = q * q * np.eye(n)
    # van Loan: expm([[-A, Qc], [0, A']] dt) = [[., Phi^-1 Qd], [0, Phi']]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -A, Qc, A.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    Qd = (Qd + Qd.T) / 2
    chans = [c for c, k in enumerate(counts) for _ in range(k)]
    Hs = [np.asarray(C, float) for C in system.C]
    w = np.ones(n) if w is None else np.asarray(w, float)
    P = 100.0 * np.eye(n)
    prev = None
    for _ in range(max_periods):
        priors = []
        for k, c in enumerate(chans):
            if k > 0 or prev is not None:
                P = Phi @ P @ Phi.T + Qd
            priors.append(P.copy())
            H = Hs[c]
            R = meas_std ** 2 * np.eye(H.shape[0])
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            I_KH = np.eye(n) - K @ H
            P = I_KH @ P @ I_KH.T + K @ R @ K.T
        if prev is not None and max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(priors, prev)) < tol:
            return float(np.mean([w @ np.diag(Pk) for Pk in priors]))
        prev = priors
    return np.inf


def grid(rate=RATE, h_min=H_MIN, tau_max=TAU_MAX, N=2):
    kmin = int(np.ceil(h_min * rate - 1e-9))
    kmax = int(np.floor(tau_max * rate + 1e-9))
    return [k for k in itertools.product(range(kmin, kmax + 1), repeat=N) if sum(k) <= kmax]


@pytest.fixture(scope="module")
def system():
    return paper_system()


WEIGHTS = [None, "agent1.*", "agent2.p_*=3,camera.*", "agent1.*=10,agent2.*"]  # optima (1,1) (9,1) (1,9) (3,1)


@pytest.fixture(scope="module")
def brute(system):
    """Oracle cost of every grid point, per weight choice."""
    out = {}
    for wt in WEIGHTS:
        w = parse_weights(wt, system)
        out[wt] = {k: oracle_cost(system, RATE, k, w=w) for k in grid()}
    return out


@pytest.mark.parametrize("wt", WEIGHTS)
def test_plan_beats_every_grid_point(system, brute, wt):
    res = plan_schedule(system, RATE, h_min=H_MIN, tau_max=TAU_MAX, weights=wt, progress=False)
    costs = brute[wt]
    best = min(costs.values())
    assert res.counts in costs
    # the plan's schedule, costed by the oracle, is at least as good as every grid point
    assert costs[res.counts] <= best * (1 + 1e-9)
    assert res.local_minimum
    assert res.tau == pytest.approx(sum(res.counts) / RATE)
    assert all(h >= H_MIN - 1e-12 for h in res.h)


@pytest.mark.parametrize("wt", WEIGHTS)
def test_cost_matches_independent_recursion(system, brute, wt):
    J = ScheduleCost(system, RATE, weights=wt)
    for k in [(1, 1), (2, 1), (1, 5), (4, 4), (6, 3), (5, 5)]:
        assert J(k) == pytest.approx(brute[wt][k], rel=1e-6)
    # a different rate and noise, other counts: cold and warm starts agree too
    nz = NoiseModel.for_system(system, measurement_std=0.02, process_std=0.05)
    J2 = ScheduleCost(system, 20.0, nz)
    for k in [(7, 3), (10, 10), (12, 30)]:
        ref = oracle_cost(system, 20.0, k, meas_std=0.02, q=0.05)
        assert J2(k) == pytest.approx(ref, rel=1e-6)


def test_weights_parse(system):
    w = parse_weights("agent*.p_*", system)
    assert w.sum() == 4 and w[4] == 1 and w[0] == 0
    assert parse_weights(",".join(["2"] * 12), system).tolist() == [2.0] * 12
    for bad in ("1,2", "nosuch.*", ",".join(["0"] * 12), ",".join(["-1"] + ["1"] * 11)):
        with pytest.raises(InvalidArgument):
            parse_weights(bad, system)


def test_neighbourhood():
    nb = set(neighbours((3, 4)))
    assert nb == {(4, 4), (2, 4), (3, 5), (3, 3), (4, 3), (2, 5)}


def test_no_schedule_fits(system):
    with pytest.raises(InvalidArgument, match="no schedule fits"):
        plan_schedule(system, RATE, h_min=1.0, tau_max=1.5, progress=False)


def test_three_channels_orders():
    sys3 = camera_agents(3)
    res = plan_schedule(sys3, 4.0, h_min=0.25, tau_max=1.5, progress=False)
    assert len(res.counts) == 3 and res.local_minimum
    assert [a["order"] for a in res.alternatives] == [(1, 3, 2)]
    ref = {k: oracle_cost(sys3, 4.0, k) for k in grid(4.0, 0.25, 1.5, N=3)}
    assert ref[res.counts] <= min(ref.values()) * (1 + 1e-9)


def test_cli_json_and_design_command(system, capsys, tmp_path):
    png = tmp_path / "map.png"
    rc = main(["plan", "paper", "--rate", "5", "--h-min", "0.2", "--tau-max", "2", "--json",
               "--plot", str(png), "--map-size", "5"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("tau", "h", "cost", "s", "counts", "design_command", "lmi", "kalman", "paper_cycles",
                "local_minimum", "design_pattern_matches", "cost_as_designed"):
        assert key in out
    assert png.stat().st_size > 1000
    assert out["tau"] == pytest.approx(sum(out["h"]))
    assert out["cost"] == pytest.approx(oracle_cost(system, 5.0, tuple(out["counts"])), rel=1e-6)
    assert out["design_pattern_matches"] is True
    assert "certified_rate" in out["kalman"]
    assert out["lmi"]["feasible"] in (True, False)
    assert len(out["paper_cycles"]) == 4
    # the printed design command parses with the real parser and designs exactly this schedule
    argv = shlex.split(out["design_command"])
    assert argv[:2] == ["switchobs", "design"]
    args = build_parser().parse_args(argv[1:])
    assert args.gains == "kalman" and args.rate == 5.0 and args.config == "paper"
    assert args.cycle[0].matches(Cycle(out["h"]), rtol=1e-12)
    assert args.cycle[0].tau == out["tau"] and args.cycle[0].s == out["s"]
    if out["lmi"]["feasible"]:
        lmi_args = build_parser().parse_args(shlex.split(out["design_command_lmi"])[1:])
        assert lmi_args.gains == "lmi" and lmi_args.cycle[0].matches(args.cycle[0], rtol=0, atol=0)
    else:
        assert out["design_command_lmi"] is None


def test_plan_never_recommends_an_lmi_design_it_found_infeasible(capsys, monkeypatch):
    import switchobs_core.cli.plan as cli_plan

    real = cli_plan.gain_reports

    def lmi_infeasible(*a, **k):
        r = real(*a, **k)
        r["lmi"] = {"feasible": False, "reason": "gain fails its Lyapunov certificate (test)"}
        return r

    monkeypatch.setattr(cli_plan, "gain_reports", lmi_infeasible)
    assert main(["plan", "paper", "--rate", "5", "--h-min", "0.2", "--tau-max", "1"]) == 0
    text = capsys.readouterr().out
    assert "lmi gains (the paper's): infeasible: gain fails its Lyapunov certificate (test)" in text
    assert "--gains kalman" in text
    assert [ln for ln in text.splitlines() if "switchobs design" in ln and "--gains kalman" not in ln] == []
    assert "(no LMI design command: the paper's LMI gains are infeasible for this cycle" in text
    assert main(["plan", "paper", "--rate", "5", "--h-min", "0.2", "--tau-max", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["design_command_lmi"] is None


def test_cli_text_and_error(capsys):
    assert main(["plan", "paper", "--rate", "5", "--h-min", "0.2", "--tau-max", "1"]) == 0
    text = capsys.readouterr().out
    assert "planned" in text and "switchobs design paper --cycle" in text and "paper (2 s, 0.6)" in text
    assert main(["plan", "paper", "--rate", "5", "--h-min", "1", "--tau-max", "1.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no schedule fits" in err[0]


@settings(max_examples=8, deadline=None)
@given(
    w=st.lists(st.floats(0.0, 5.0), min_size=12, max_size=12).filter(lambda v: sum(v) > 0.1),
    meas=st.sampled_from([1e-3, 1e-2, 0.1]),
)
def test_optimum_is_local_minimum(system, w, meas):
    nz = NoiseModel.for_system(system, measurement_std=meas)
    res = plan_schedule(system, RATE, nz, weights=w, h_min=H_MIN, tau_max=1.6, progress=False)
    kmax = int(1.6 * RATE + 1e-9)
    best = oracle_cost(system, RATE, res.counts, meas_std=meas, w=w)
    assert res.cost == pytest.approx(best, rel=1e-6)
    for k in neighbours(res.counts):
        if min(k) >= 1 and sum(k) <= kmax:
            assert oracle_cost(system, RATE, k, meas_std=meas, w=w) >= best * (1 - 1e-9)
