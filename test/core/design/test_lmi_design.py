"""eta_min, cycle designs, robust designs (Sec. s:LMI_Gain), N = 3 channels."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core import paper as P
from switchobs_core.design.lmi import Designer, Margin
from switchobs_core.exceptions import InfeasibleDesign, InvalidArgument, ScheduleError, SwitchobsError
from switchobs_core.model.scenarios import camera_agents
from switchobs_core.model.schedule import Cycle


@pytest.mark.parametrize("row", P.TABLE, ids=[f"{r[0]}" for r in P.TABLE])
def test_paper_table_of_eta_min_reproduced(paper_designer, row):
    (tau, s), emin_paper, _ = row
    emin = paper_designer.eta_min(Cycle.from_ts(tau, s))
    assert emin == pytest.approx(emin_paper, abs=0.01)


@pytest.mark.parametrize("tau, s", [(2.0, 0.6), (1.0, 0.2), (5.0, 0.9)])
def test_eta_min_is_the_fixed_point_with_closed_form_kappa(paper_designer, tau, s):
    # e:eta1_fixed / e:eta2_fixed evaluated with the closed-form kappa (independent of the SDP).
    c = Cycle.from_ts(tau, s)
    emin = paper_designer.eta_min(c)
    for i in range(2):
        h, u = c.h[i], c.inactive(i + 1)
        d = P.D_OFFSETS[i]
        mu = d / 2 + math.sqrt(d * d / 4 + 0.25)  # closed-form log norm of the agent block
        rhs = (mu * u + math.log(P.kappa_closed_form(emin[i], i + 1) / 0.99)) / h
        assert emin[i] == pytest.approx(rhs, abs=1e-5)
        # smallest: just below it the inequality fails
        e = emin[i] - 1e-3
        assert e * h < mu * u + math.log(P.kappa_closed_form(e, i + 1) / 0.99)


def test_cycle_design_is_consistent(paper, paper_designer):
    d = paper_designer.design(Cycle.from_ts(2.0, 0.6))
    assert d.certified
    for i, ch in enumerate(d.channels):
        dec = paper.decomposition(i + 1)
        # L_i = T_i [L_o; 0]: no component along the unobservable subspace (e:L_original)
        assert np.allclose(dec.T_u.T @ ch.L, 0, atol=1e-14)
        assert np.allclose(dec.T_o.T @ ch.L, ch.L_o)
        # the observable block of A - L_i C_i is Lambda_o = A_o - L_o C_o
        Lam = dec.T_o.T @ (paper.A - ch.L @ paper.C[i]) @ dec.T_o
        assert np.allclose(Lam, dec.A_o - ch.L_o @ dec.C_o, atol=1e-12)
        # eta = eta_min * 1.05 (default relative margin); f recomputed from its definition
        assert ch.eta == pytest.approx(ch.eta_min * 1.05)
        expected_f = ch.kappa * math.exp(ch.mu * (2.0 - d.cycle.h[i]) - ch.eta * d.cycle.h[i])
        assert ch.f == pytest.approx(expected_f, rel=1e-12) and ch.f <= 0.99
        # the bound kappa e^{-eta t} holds for the embedded closed loop on the observable part
        for t in (0.2, 1.0, 2.5):
            assert np.linalg.norm(expm(Lam * t), 2) <= ch.kappa * math.exp(-ch.eta * t) * (1 + 1e-9)


def test_explicit_paper_rates_recorded(paper_designer):
    d = paper_designer.design(Cycle.from_ts(*P.PERIODIC), eta=P.PERIODIC_ETA)
    assert d.eta == P.PERIODIC_ETA and d.certified
    # kappa at eta = 1.6 and 3.5 vs the closed form
    assert d.kappa[0] == pytest.approx(P.kappa_closed_form(1.6, 1), rel=1e-4)
    assert d.kappa[1] == pytest.approx(P.kappa_closed_form(3.5, 2), rel=1e-4)


def test_design_does_not_depend_on_order(paper):
    cycles = [Cycle.from_ts(*r[0]) for r in P.TABLE]
    a = Designer(paper).table(cycles)
    b = Designer(paper).table(cycles[::-1])
    for c in cycles:
        for La, Lb in zip(a.lookup(c).L, b.lookup(c).L):
            assert np.array_equal(La, Lb)


def test_three_channels_designed_and_verified():
    s = camera_agents(3)
    des = Designer(s, delta=0.95, margin=Margin("absolute", 0.1))
    c = Cycle((1.0, 1.2, 0.8))
    d = des.design(c)
    assert d.N == 3 and d.certified
    for i, ch in enumerate(d.channels):
        assert ch.eta == pytest.approx(ch.eta_min + 0.1)
        dec = s.decomposition(i + 1)
        Lam = dec.A_o - ch.L_o @ dec.C_o
        assert np.max(np.linalg.eigvals(Lam).real) < -ch.eta
        u = c.tau - c.h[i]
        assert ch.f == pytest.approx(ch.kappa * math.exp(ch.mu * u - ch.eta * c.h[i])) and ch.f <= 0.95


@settings(max_examples=25, deadline=None)
@given(h=st.lists(st.floats(0.8, 1.2), min_size=2, max_size=2))
def test_robust_design_covers_every_cycle_in_the_box(robust_design, h):
    chk = robust_design.certifies(Cycle(h))
    assert chk.ok and chk.dominated
    assert all(f <= 0.99 for f in chk.f)


@pytest.fixture(scope="module")
def robust_design(paper_designer):
    return paper_designer.design_robust(0.8, 1.2)


def test_robust_worst_case_is_a_design_point(paper_designer, robust_design):
    # worst case of the box: active h_min = 0.8, inactive h_max = 1.2 -> the (2, 0.4) cycle for channel 1
    emin = paper_designer.eta_min(Cycle((0.8, 1.2)))
    assert robust_design.eta_min[0] == pytest.approx(emin[0])
    assert robust_design.channels[0].active == 0.8 and robust_design.channels[0].inactive == 1.2


@pytest.mark.parametrize(
    "make, exc, match",
    [
        (lambda: Cycle.from_ts(2.0, 1.5), ScheduleError, r"s must lie in \(0, 1\)"),
        (lambda: Cycle.from_ts(2.0, 0.0), ScheduleError, r"s must lie in \(0, 1\)"),
        (lambda: Cycle.from_ts(-1.0, 0.5), ScheduleError, "tau must be > 0"),
        (lambda: Cycle.from_ts(0.0, 0.5), ScheduleError, "tau must be > 0"),
        (lambda: Cycle((1.0, float("nan"))), ScheduleError, "h_2 must be finite"),
    ],
)
def test_bad_cycles(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


def test_infeasible_request_is_a_clear_error(paper_designer):
    msg = r"cycle \(20 s, 5e-07\), channel 1: no decay rate up to .*lengthen the active time"
    with pytest.raises(InfeasibleDesign, match=msg) as e:
        paper_designer.design(Cycle((1e-5, 20.0)))
    assert isinstance(e.value, SwitchobsError)
    with pytest.raises(InfeasibleDesign, match="increase the margin"):
        Designer(paper_designer.system, margin=Margin("absolute", 0.0)).design(Cycle.from_ts(2.0, 0.6))


def test_bad_design_arguments(paper, paper_designer):
    with pytest.raises(InvalidArgument, match=r"delta must lie in \(0, 1\)"):
        Designer(paper, delta=1.0)
    with pytest.raises(InvalidArgument, match="delta must be one number or 2 numbers"):
        Designer(paper, delta=[0.9, 0.9, 0.9])
    with pytest.raises(ScheduleError, match="has 3 channels; the system has 2"):
        paper_designer.design(Cycle((1, 1, 1)))
    with pytest.raises(InvalidArgument, match="eta must give 2 positive rates"):
        paper_designer.design(Cycle.from_ts(2, 0.6), eta=(1.0,))
    with pytest.raises(ScheduleError, match="h_min <= h_max"):
        paper_designer.design_robust(1.2, 0.8)
    assert Margin.parse("5%") == Margin("relative", 0.05) and Margin.parse("0.2") == Margin("absolute", 0.2)
    with pytest.raises(InvalidArgument, match="cannot parse margin"):
        Margin.parse("lots")
