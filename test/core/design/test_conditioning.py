"""Designs that the theory admits succeed whatever the CPU's rounding (scaled SDP, verified
back-offs), and cycles no rate can serve are refused with the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.certificate import cycle_factor
from switchobs_core.cli import main
from switchobs_core.design.lmi import ETA_GRID, Designer
from switchobs_core.design.synthesis import LMISynthesizer, verify_gain
from switchobs_core.exceptions import InfeasibleDesign
from switchobs_core.model.scenarios import load_system, paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import LTISystem
from switchobs_core.sim.figures import eta_min_figures

CART_PAIR = """\
name: cart_pair
states: [p1, v1, p2, v2]
A: [[0, 1, 0, 0], [0, -0.1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0.05]]
B: [[0], [1], [0], [0]]
channels:
  - {name: left,  C: [[1, 0, 0, 0]]}
  - {name: right, C: [[1, 0, -1, 0]]}
"""


def _scaled(system: LTISystem, factor: float) -> LTISystem:
    return LTISystem(system.A * factor, system.B, system.C, name=system.name)


def _check_verified(design, system):
    """Every gain passes the floating-point Lyapunov check at its rate, and f is the paper's factor."""
    for i, ch in enumerate(design.channels):
        dec = system.decompositions[i]
        eta_v, kappa, _ = verify_gain(dec.A_o, dec.C_o, ch.L_o, ch.P, ch.eta)
        assert eta_v >= ch.eta
        assert kappa == pytest.approx(ch.kappa, rel=1e-9)
        assert ch.f == pytest.approx(cycle_factor(kappa, ch.mu, ch.eta, ch.active, ch.inactive), rel=1e-12)
        assert ch.f <= design.delta[i]


def test_sdp_is_dpp():
    syn = LMISynthesizer([[0.0, 1.0], [0.0, 0.0]], [[1.0, 0.0]])
    assert syn.is_dpp()


@pytest.mark.parametrize("factor", [1 - 1e-12, 1.0, 1 + 1e-12])
def test_paper_corner_tau1_s001_designs(factor):
    """The figure grid's hardest corner (channel 1 active 10 ms, eta_min ~ 700) designs and verifies."""
    system = _scaled(paper_system(), factor)
    des = Designer(system)
    cyc = Cycle.from_ts(1.0, 0.01)
    d = des.design(cyc)
    assert d.eta[0] > 300                      # a large rate: the regime that used to fail
    _check_verified(d, system)


@pytest.fixture(scope="module")
def cart_pair(tmp_path_factory):
    p = tmp_path_factory.mktemp("sys") / "cart_pair.yaml"
    p.write_text(CART_PAIR)
    return load_system(p)


@pytest.mark.parametrize("ts", [(2.0, 0.6), (2.0, 0.5), (2.0, 0.4), (1.0, 0.5), (4.0, 0.5), (4.0, 0.3), (10.0, 0.5)])
def test_cart_pair_readme_cycles_design(cart_pair, ts):
    des = Designer(cart_pair)
    d = des.design(Cycle.from_ts(*ts))
    _check_verified(d, cart_pair)
    # the right channel's observable part has dimension 3: kappa grows like eta^2, so its
    # eta_min is far above the left channel's for the same active time
    assert d.eta_min[1] > d.eta_min[0] or ts[1] < 0.5
    assert d.kappa[1] > d.eta[1] ** 2          # kappa ~ c eta^2 on the 3-dimensional channel


def test_no_rate_even_with_kappa_one_is_refused_without_sdps():
    des = Designer(paper_system())
    with pytest.raises(InfeasibleDesign, match=r"channel 1: .*even with kappa = 1, f = .* > delta"):
        des.design(Cycle.from_ts(2.0, 1e-5))
    # the bound used: exp(mu u - eta_max h) > delta at the largest grid rate
    ch = des.channels[0]
    assert math.exp(ch.mu * 2.0 * (1 - 1e-5) - ETA_GRID[-1] * 2e-5) > 0.99
    assert ch.synth.n_solves == 0


def test_figure_marks_points_without_a_rate(tmp_path):
    des = Designer(paper_system())
    paths = eta_min_figures(des, tmp_path, taus=[1.0, 2.0], s_values=[1e-5, 0.5], progress=False)
    assert [p.name for p in paths] == ["eta_min1.png", "eta_min2.png"]
    assert all(p.stat().st_size > 1000 for p in paths)
    grid = des.eta_min_map([2.0], [1e-5, 0.5], progress=False)
    assert np.isnan(grid[0, 0, 0]) and np.isfinite(grid[0, 1]).all()


def test_cli_eta_sets_rates_and_reports_the_paper_condition(tmp_path, capsys):
    out = tmp_path / "g.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--eta", "1.6,3.5", "-o", str(out), "--json"]) == 0
    import json

    res = json.loads(capsys.readouterr().out)
    d = res["designs"][0]
    assert d["eta"] == [1.6, 3.5]
    assert all(f <= 0.99 for f in d["f"]) and d["paper_condition_holds"]
    assert main(["design", "paper", "--cycle", "2,0.6", "--eta", "1.0,3.5", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "channel 1: f = " in text and "> delta = 0.99: the paper's condition fails" in text
    assert "channel 2: f =" not in text


def test_cli_eta_count_must_match_cycles(tmp_path, capsys):
    code = main(["design", "paper", "--cycle", "2,0.6", "--cycle", "4,0.5", "--cycle", "3,0.6",
                 "--eta", "1.6,3.5", "--eta", "1.2,1.1", "-o", str(tmp_path / "g.json")])
    assert code != 0
    assert "--eta was given 2 times for 3 cycles" in capsys.readouterr().err
    assert not (tmp_path / "g.json").exists()


@pytest.mark.parametrize("factor", [1 - 1e-12, 1 + 1e-12])
def test_reproduce_grid_is_designable_under_perturbed_rounding(factor):
    """Every point of the paper's figure grid has an eta_min (the theory admits them all),
    whichever way A is rounded."""
    from switchobs_core.sim.figures import S_VALUES, TAUS

    des = Designer(_scaled(paper_system(), factor))
    grid = des.eta_min_map(TAUS, S_VALUES, progress=False)
    assert np.isfinite(grid).all(), np.argwhere(~np.isfinite(grid))
    assert grid.max() > 300                    # the corner (1 s, 0.01) is in the grid


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    damping=st.floats(-0.3, 0.3),
    log_eta=st.floats(math.log(0.05), math.log(800.0)),
    scale=st.sampled_from([1 - 1e-12, 1.0, 1 + 1e-12]),
)
def test_gain_verifies_over_a_wide_range_of_rates(damping, log_eta, scale):
    """Position-measured second-order systems (r = 2, kappa ~ 2 eta): the gain at any rate
    up to 800 is found and passes the floating-point check at that rate."""
    eta = math.exp(log_eta)
    A = np.array([[0.0, 1.0], [0.0, damping]]) * scale
    C = np.array([[1.0, 0.0]])
    g = LMISynthesizer(A, C).gain(eta)
    eta_v, kappa, ab = verify_gain(A, C, g.L_o, g.P, eta)
    assert eta_v >= eta and ab < -eta
    assert kappa == pytest.approx(g.kappa, rel=1e-9)
