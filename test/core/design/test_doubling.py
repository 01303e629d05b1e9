"""The periodic Riccati equation by doubling against the plain iteration and the equation itself;
the triple composition; the square-root step; memory of the plain iteration; large camera models."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from switchobs_core.design.doubling import (
    RiccatiMap,
    closed_loop_transition,
    solve_periodic_riccati,
)
from switchobs_core.design.kalman import check_detectable, design_kalman, sample_pattern
from switchobs_core.design.riccati import Step, discretize, periodic_riccati
from switchobs_core.exceptions import RiccatiError, UndetectableSchedule
from switchobs_core.model.detectability import undetectable_modes
from switchobs_core.model.noise import default_noise
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.numerics.kalman_step import joseph, riccati_step, sqrt_correct

PAPER = paper_system()


def _rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _steps(system, cycles, rate, noise=None):
    """The design's step sequence of one period (full rows, or the common rows when blind)."""
    noise = default_noise(system) if noise is None else noise
    pat = sample_pattern(cycles, rate)
    Phi, _, Qd = discretize(system.A, system.B, noise.Q_c, 1.0 / rate)
    out = []
    for k, c in enumerate(pat.channels):
        r = pat.rows(k, system)
        out.append(Step(Phi, Qd, system.C[c - 1] if r is None else system.C[c - 1][list(r)], noise.R(c, r)))
    return out, noise


CASES = {
    "paper (2 s, 0.6)": (PAPER, [Cycle.from_ts(2.0, 0.6)], 50.0),
    "three agents": (camera_agents(3), [Cycle((0.4, 0.3, 0.5))], 20.0),
    "dead time (blind phases)": (PAPER, [Cycle((0.5, 0.5), 0.1)], 50.0),
    "sequence of cycles": (PAPER, [Cycle((0.6, 0.4)), Cycle((0.3, 0.7)), Cycle((0.5, 0.5), 0.1)], 20.0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_doubling_equals_iteration_and_solves_the_equation(case):
    """Every phase's prior and gain from the doubling equals the plain iteration's (rtol 1e-9), and
    one period of the Joseph-form recursion from the doubling's prior of phase 0 reproduces every
    stored prior (the periodic Riccati equation's residual) within 1e-10."""
    system, cycles, rate = CASES[case]
    steps, noise = _steps(system, cycles, rate)
    dbl = solve_periodic_riccati(steps)
    it = periodic_riccati(steps, noise.P0, startup_rtol=0.0)
    assert len(dbl.P_prior) == len(it.P_prior) == len(steps)
    assert dbl.doublings >= 1 and it.periods > dbl.periods - dbl.doublings
    for k in range(len(steps)):
        assert _rel(dbl.P_prior[k], it.P_prior[k]) <= 1e-9, k
        if steps[k].H.shape[0]:
            assert _rel(dbl.K[k], it.K[k]) <= 1e-9, k
    # residual: P^-_{k+1} = Phi (Joseph correction of P^-_k) Phi' + Q_d, around the whole period
    P = dbl.P_prior[0]
    K = len(steps)
    for k in range(1, K + 1):
        st, nx = steps[k - 1], steps[k % K]
        _, Pp = riccati_step(P, st.H, st.R)
        P = nx.Phi @ Pp @ nx.Phi.T + nx.Q_d
        assert _rel(P, dbl.P_prior[k % K]) <= 1e-10, k
    # the stabilising solution: the period's closed-loop error map contracts
    assert 0 < dbl.rho < 1
    assert np.array_equal(dbl.transition, closed_loop_transition(steps, dbl.K))
    if any(st.H.shape[0] < steps[0].H.shape[0] for st in steps):     # blind phases were exercised
        assert case in ("dead time (blind phases)", "sequence of cycles")


def test_composition_of_triples():
    """(f2 o f1)(X) = f2(f1(X)) and F.doubled()(X) = F(F(X)) for random PSD triples (1e-12)."""
    rng = np.random.default_rng(7)
    n = 5

    def psd(scale=1.0, rank=n):
        B = rng.standard_normal((n, rank))
        return scale * B @ B.T

    f1 = RiccatiMap(rng.standard_normal((n, n)), psd(rank=2), psd(0.1))
    f2 = RiccatiMap(rng.standard_normal((n, n)), psd(rank=3), psd(0.2))
    X = psd()
    assert _rel(f1.then(f2)(X), f2(f1(X))) <= 1e-12
    assert _rel(f1.doubled()(X), f1(f1(X))) <= 1e-12
    # identity triple (I, 0, 0) is neutral
    e = RiccatiMap(np.eye(n), np.zeros((n, n)), np.zeros((n, n)))
    assert _rel(e.then(f1)(X), f1(X)) <= 1e-13


def test_square_root_correction_equals_joseph():
    """The QR correction gives the Joseph form's gain and posterior (1e-12) from a non-square factor."""
    rng = np.random.default_rng(3)
    n, p = 6, 2
    L = rng.standard_normal((n, 2 * n))
    H = rng.standard_normal((p, n))
    R = np.diag([0.3, 0.05])
    K, Lp, Ss = sqrt_correct(L, H, np.sqrt(R))
    P = L @ L.T
    K0, Pp = riccati_step(P, H, R)
    assert _rel(K, K0) <= 1e-12
    assert _rel(Lp @ Lp.T, Pp) <= 1e-12 and Lp.shape == (n, n)
    assert _rel(Ss @ Ss.T, H @ P @ H.T + R) <= 1e-12
    assert _rel(joseph(P, K, H, R), Pp) <= 1e-12


def test_unexcited_marginal_mode_is_refused():
    """A double integrator without process noise has no stabilising solution: the doubling lands on
    P = 0 (gain 0), and the closed-loop check refuses it."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    Phi, _, _ = discretize(A, np.zeros((2, 0)), np.zeros((2, 2)), 0.1)
    steps = [Step(Phi, np.zeros((2, 2)), np.array([[1.0, 0.0]]), np.array([[1e-2]]))]
    with pytest.raises(RiccatiError, match=r"not stabilising \(closed-loop spectral radius per period 1\b.*"
                                           r"increase Q_c"):
        solve_periodic_riccati(steps)


def test_plain_iteration_keeps_two_periods():
    """The plain iteration's memory does not grow with the periods it runs: its peak is under three
    periods of priors (it kept every prior of the run before)."""
    system = camera_agents(4)
    steps, noise = _steps(system, [Cycle((1.0, 1.0, 1.0, 1.0))], 50.0)
    n, K = system.n, len(steps)
    tracemalloc.start()
    try:
        sol = periodic_riccati(steps, noise.P0, startup_rtol=0.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert sol.periods >= 4
    assert peak < 3 * K * n * n * 8


@pytest.mark.slow
def test_plain_iteration_settles_at_the_rounding_floor_for_16_agents():
    """camera_agents(16): the plain iteration stops at its rounding floor (it raised 'did not converge
    in 500 periods (1.7e-11 > 1e-12)'), and agrees with the doubling within 1e-7."""
    system = camera_agents(16)
    steps, noise = _steps(system, [Cycle([1.0] * 16)], 50.0)
    it = periodic_riccati(steps, noise.P0, startup_rtol=0.0, max_periods=40)
    dbl = solve_periodic_riccati(steps)
    assert it.change <= 1e-8 and dbl.change <= 1e-8
    assert max(_rel(a, b) for a, b in zip(it.P_prior, dbl.P_prior)) <= 1e-7


@pytest.mark.slow
def test_camera_agents_16_designs():
    """The 50 Hz Kalman design of camera_agents with 16 agents (every h_i = 1 s) completes (it failed
    after 190 s and 14.9 GiB before): a contraction per period, its start-up complete."""
    system = camera_agents(16)
    kd = design_kalman(system, Cycle([1.0] * 16), 50.0)
    assert kd.pattern.K == 800 and len(kd.periodic) == 800
    assert 0 < kd.rho < 0.2 and kd.change <= 1e-8
    assert 0 < len(kd.startup) <= 64 * 800 and kd.startup_change <= 1e-11


def test_camera_states_of_32_agents_are_detectable():
    """The 32-agent model at 50 Hz (every h_i = 1 s) is detectable (it was refused: '94 mode(s) ...
    |lambda| >= 1', integrators among them), and a schedule whose last agent gets no sample is refused
    naming that agent's modes, and only its own."""
    system = camera_agents(32)
    check_detectable(system, sample_pattern(Cycle([1.0] * 32), 50.0))
    pat = sample_pattern(Cycle([1.0] * 30 + [1.05, 0.05]), 10.0)     # agent 32: [31.05, 31.1) s, no sample
    assert pat.K == 311 and 32 not in pat.channels
    want = (r"not detectable: 3 mode\(s\) .*growth rates 0, 0, 0\.05161 1/s.*agent32\.p_x.*agent32\.v_y"
            r".*Channel\(s\) \[32\]")
    with pytest.raises(UndetectableSchedule, match=want) as err:
        check_detectable(system, pat)
    assert "agent31" not in str(err.value) and "camera" not in str(err.value)


def test_aliased_oscillator_is_undetectable():
    """An undamped oscillator sampled once per period with w T = 2 pi aliases both modes onto
    mu = 1: the velocity direction is never seen (grouped PBH test); with w T = pi / 2 it is seen."""
    w = 3.0
    A = np.array([[0.0, w], [-w, 0.0]])
    H = [np.array([[1.0, 0.0]])]
    bad = undetectable_modes(A, H, 2 * np.pi / w)
    assert len(bad) == 1 and abs(bad[0].lam.real) < 1e-12
    assert np.allclose(np.abs(bad[0].v), [0.0, 1.0], atol=1e-9)
    assert undetectable_modes(A, H, 0.5 * np.pi / w) == []
    # a stable mode is never reported, seen or not
    assert undetectable_modes(np.diag([-1.0, -2.0]), [np.zeros((1, 2))], 0.1) == []
