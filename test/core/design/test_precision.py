"""Designs beyond double precision are refused at design time with one line, and designs within it
are not: the Kalman design (before its doubling and after it), the LMI design, and plan's search."""

from __future__ import annotations

import re

import numpy as np
import pytest

import switchobs_core.design.kalman as design_kalman_module
from switchobs_core.design.kalman import design_kalman
from switchobs_core.design.lmi import Designer
from switchobs_core.design.plan import ScheduleCost, plan_schedule
from switchobs_core.design.precision import (
    PRECISION_RANGE,
    beyond_precision,
    covariance_span,
    cycle_stretches,
    pattern_stretches,
    state_scale,
    unseen_growth,
)
from switchobs_core.exceptions import DesignError, PrecisionError
from switchobs_core.model.noise import default_noise
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle


def _growing_agents(M: int):
    """The camera model whose agent j >= 3 has the velocity mode 0.1 + 0.03 (j - 2) per second (up to
    1.0/s at M = 32): ever faster unstable modes as M grows."""
    return camera_agents(M, D_agents=[(0.0, 0.2), (0.0, 0.1)] + [(0.0, 0.1 + 0.03 * (j - 2)) for j in range(3, M + 1)])


def _span(system, kd) -> float:
    return covariance_span(system, [ph.P_prior for ph in kd.periodic]).span


def test_growing_32_agents_refused_before_the_doubling(monkeypatch):
    """32 agents with modes up to 1/s, every residence 1 s, 50 Hz: each agent unseen 31 s, its error
    growing 4e13-fold meanwhile, so the covariance would span at least 1.7e27. Refused in one line
    that names the precision problem, the numbers and the fix, before any Riccati step."""
    def no_doubling(*_, **__):
        raise AssertionError("the doubling ran")
    monkeypatch.setattr(design_kalman_module, "solve_periodic_riccati", no_doubling)
    with pytest.raises(PrecisionError) as err:
        design_kalman(_growing_agents(32), Cycle([1.0] * 32), 50.0)
    msg = str(err.value)
    assert "\n" not in msg and isinstance(err.value, DesignError)
    assert "beyond double precision" in msg and "h = 1 s on all 32 channels at 50 Hz" in msg
    assert "channel 32 (agent32) goes unseen for 31 s" in msg and "at most 1e12 fits" in msg
    m = re.search(r"grows ([0-9.e+]+)-fold .* at least ([0-9.e+]+) .* no channel goes unseen for more than "
                  r"([0-9.]+) s \(equal residences of at most ([0-9.]+) s\)", msg)
    assert m, msg
    g, need, fit, h = (float(v) for v in m.groups())
    assert g > 1e12 and need == pytest.approx(g * g, rel=1e-2)
    assert 5.0 < fit < 31.0 and h == pytest.approx(fit / 31, rel=1e-2)


@pytest.mark.slow
def test_refused_after_the_doubling_from_the_span_of_its_covariance():
    """20 growing agents: each unseen 19 s; the growth of what only one agent sees (g^2 = 2e10) fits,
    the periodic covariance itself (1.4e13: the velocity's variance against the camera's position)
    does not."""
    system = _growing_agents(20)
    pattern = design_kalman_module.design_pattern(system, Cycle([1.0] * 20), 50.0)
    st = pattern_stretches(pattern.channels, pattern.blind, 50.0, 20)
    assert max(u.growth for u in unseen_growth(system, st)) ** 2 < PRECISION_RANGE
    want = (r"its periodic covariance spans [0-9.]+e\+1[3-9] .*agent20.*"
            r"channel 20 \(agent20\), whose directions grow most, goes unseen for 19 s")
    with pytest.raises(PrecisionError, match=want):
        design_kalman(system, Cycle([1.0] * 20), 50.0, max_startup=0)


@pytest.mark.parametrize("name,system,cycle,rate", [
    ("paper", paper_system(), Cycle.from_ts(2.0, 0.6), 50.0),
    ("8 agents", camera_agents(8), Cycle([1.0] * 8), 50.0),
    pytest.param("32 agents at 0.05/s", camera_agents(32, D_agents=[(0.0, 0.05)] * 32), Cycle([1.0] * 32), 50.0,
                 marks=pytest.mark.slow),
])
def test_well_posed_designs_accepted(name, system, cycle, rate):
    """The paper's model, 8 agents and 32 agents whose modes are all 0.05/s design, their periodic
    covariances spanning far less than the limit; the growth of each channel's unseen directions,
    squared, is a lower bound of that span (design/precision's argument). The span is checked
    against its definition computed here: ``max_k lambda_max / min_k lambda_min`` of the priors
    in the balanced coordinates ``D^-1 P D^-1``."""
    kd = design_kalman(system, cycle, rate, max_startup=0)
    got = _span(system, kd)
    d = state_scale(system)
    eig = [np.linalg.eigvalsh(ph.P_prior / np.outer(d, d)) for ph in kd.periodic]
    want = max(w[-1] for w in eig) / min(w[0] for w in eig)
    assert got == pytest.approx(want, rel=1e-9) and got < 1e-4 * PRECISION_RANGE
    st = pattern_stretches(kd.pattern.channels, kd.pattern.blind, rate, system.N)
    assert max(u.growth for u in unseen_growth(system, st)) ** 2 <= got


def test_growth_bounds_the_span_from_below_where_agents_grow_fast():
    """Also with growth far from 1 (6 growing agents, residences 3 s: unseen 15 s): g^2 <= span."""
    system = _growing_agents(6)
    kd = design_kalman(system, Cycle([3.0] * 6), 10.0, max_startup=0)
    st = pattern_stretches(kd.pattern.channels, kd.pattern.blind, 10.0, 6)
    g = max(u.growth for u in unseen_growth(system, st))
    assert 1e3 < g ** 2 <= _span(system, kd)


def test_pattern_stretches():
    """From the first sample after a view to the next view; blind samples are no views; a channel
    never viewed has none."""
    assert pattern_stretches([1, 1, 2, 2, 2], (), 10.0, 2) == (0.3, 0.2)
    assert pattern_stretches([1, 1, 2, 2, 2], (False, False, True, False, False), 10.0, 2) == (0.3, 0.3)
    assert pattern_stretches([1, 1, 1], (), 10.0, 2) == (0.0, np.inf)
    assert cycle_stretches((1.0, 2.0, 3.0), 0.5) == (5.5, 4.5, 3.5)


def test_lmi_design_refused_before_its_sdps():
    """The LMI design of the growing 32 agents: the cycle's error map would pass through a growth of
    4e13 (> 1e12): refused in _check_cycle, before a curve or an SDP exists; so is a robust box as
    long; the well-posed 32 agents' cycle fits (g = 74)."""
    des = Designer(_growing_agents(32))
    with pytest.raises(PrecisionError) as err:
        des.design(Cycle([1.0] * 32))
    msg = str(err.value)
    assert "the LMI design of cycle h = 1 s on all 32 channels is beyond double precision" in msg
    assert re.search(r"error map of a cycle passes through at least [0-9.]+e\+1[3-9]", msg) and "\n" not in msg
    assert all(ch.curve.points()[0].size == 0 for ch in des.channels)
    with pytest.raises(PrecisionError, match="the robust design h in"):
        des.design_robust(0.9, 1.1)
    assert beyond_precision(camera_agents(32, D_agents=[(0.0, 0.05)] * 32), cycle_stretches([1.0] * 32),
                            power=1, what="x") == ""


def test_plan_skips_schedules_beyond_double_precision():
    """plan's candidates beyond double precision cost inf and are counted; a box where every one is
    refuses with PrecisionError; a box with some is planned among the others."""
    system = camera_agents(2, D_agents=[(0.0, 1.5), (0.0, 0.1)])
    J = ScheduleCost(system, 5.0, default_noise(system))
    with pytest.raises(PrecisionError, match=r"undetectable or beyond double precision \(\d+ of them, e\.g\. the "
                                             r"schedule of .* goes unseen"):
        plan_schedule(system, 5.0, h_min=20.0, tau_max=60.0, cost=J, orders=False)
    J2 = ScheduleCost(system, 5.0, default_noise(system))
    res = plan_schedule(system, 5.0, h_min=1.0, tau_max=40.0, cost=J2, orders=False)
    assert np.isfinite(res.cost) and J2.beyond > 0 and res.tau < 40.0
