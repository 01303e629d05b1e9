"""Recovery of the guarantee around the observer: an unknown e0 gives no bound until a window of
data certifies one (which then holds), the bounds restart from a certified radius, a body the gate
starves is re-initialised from its own samples, and which states a channel alone observes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.bounds.rigorous import NO_E0
from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.consistency import InnovationTest
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.runtime.recovery import Recovery, body_states, cycle_span
from switchobs_core.table.gains import kalman_table

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
VMAX = 0.03
X0 = np.array([0, 0, 0.1, 0, 1, 2, 0.2, -0.1, -1, 3, 0, 0.2], float)


def _paper_samples(paper, seconds: float):
    """The paper's system from X0 at RATE on the (2 s, 0.6) schedule (the plant stepped by its exact
    transition in double): ``(k, t, active channel, state)`` for each sample up to ``seconds``."""
    sched = PeriodicSchedule(CYC)
    F = expm(paper.A / RATE)
    x = X0.copy()
    for k in range(int(seconds * RATE) + 1):
        if k:
            x = F @ x
        t = k / RATE
        yield k, t, sched.channel_at(t), x


@pytest.fixture(scope="module")
def ktable(paper):
    nm = NoiseModel(meas_std=((0.01,) * 4,) * 2, Q_c=1e-4 * np.eye(12), P0=100 * np.eye(12))
    return kalman_table(paper, [design_kalman(paper, CYC, RATE, nm)])


def test_body_states_are_the_states_only_that_channel_observes(paper):
    assert body_states(paper.A, paper.C, 1) == [4, 5, 6, 7]        # agent1
    assert body_states(paper.A, paper.C, 2) == [8, 9, 10, 11]      # agent2


def test_unknown_e0_gives_no_bound_until_the_data_certify_one(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0 + 3.0, e0=None, noise_max=VMAX)
    assert obs.e0 is None and obs.bounds_withdrawn == NO_E0
    env = obs.envelope()
    assert math.isinf(env.exact_bound) and math.isinf(env.noise_bound) and env.paper_bound == -1.0
    rec = Recovery(obs)
    assert cycle_span(obs) == 2.0
    rng = np.random.default_rng(3)
    first = None
    for _k, t, c, x in _paper_samples(paper, 4.0):
        y = paper.C[c - 1] @ x + rng.uniform(-VMAX, VMAX, 4)
        assert rec.before(t, c, None, y) == ""
        obs.update(t, c, y)
        cert = rec.after(t, c, None, y, first is not None)
        if cert is not None:
            first = t
            assert obs.bounds_withdrawn == ""
            assert cert.t == t and cert.t_start == 0.0
        nb = obs.envelope().noise_bound
        if first is None:
            assert math.isinf(nb)
        else:       # the bound holds from the re-certification on (the plant in double: its rounding
            assert np.linalg.norm(obs.x_hat - x) <= nb + 1e-9      # is far below the noise's centimetres)
    assert first == 2.0         # one full cycle of data
    assert rec.recertifications == 1


def test_recertify_restarts_the_rigorous_bounds_from_the_ball(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0, e0=5.0, noise_max=VMAX)
    obs.update(0.0, 1, paper.C[0] @ X0)
    assert obs.recertify(0.25)
    env = obs.envelope()
    assert 0.25 <= env.noise_bound <= 0.25 * (1 + 1e-12) and 0.25 <= env.exact_bound <= 0.25 * (1 + 1e-12)
    lmi_measurement = SwitchedObserver(paper, ktable, "periodic", [CYC], e0=None, family="kalman-online",
                                       rounding_bound=False)
    assert not lmi_measurement.recertify(0.25)      # no rigorous sets are kept: nothing to restart


def test_a_starved_body_is_reinitialised_from_its_own_samples(paper, ktable):
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0, e0=1.0, noise_max=VMAX)
    obs.update(0.0, 1, paper.C[0] @ X0)
    rec = Recovery(obs, starve=10)
    # agent1 turned: the plant's agent1 now moves at (1, -1) m/s from another place
    truth = X0.copy()
    truth[4:8] = [3.0, -1.0, 1.0, -1.0]
    F = expm(paper.A / RATE)
    rng = np.random.default_rng(0)
    why = ""
    x = truth.copy()
    before = obs.predict(10 / RATE)
    for k in range(1, 11):
        x = F @ x if k > 1 else x
        why = rec.rejected(k / RATE, 1, None, paper.C[0] @ x + rng.uniform(-0.003, 0.003, 4)) or why
    assert "model failure" in why and "[4, 5, 6, 7]" in why and rec.reinits == 1
    est = obs.x_hat
    assert np.linalg.norm(est[4:6] - x[4:6]) < 0.01        # position within 1 cm (3 mm noise)
    assert np.linalg.norm(est[6:8] - x[6:8]) < 0.5         # velocity from 10 samples over 0.18 s
    assert obs.t == 10 / RATE
    assert np.array_equal(est[:4], before[:4]) and np.array_equal(est[8:], before[8:])     # the others untouched
    # an accepted sample ends a run of rejections: 9 more rejections are not a model failure
    rec.rejected(0.3, 2, None, np.zeros(4))
    rec.accepted(2)
    assert all(rec.rejected(0.3 + k / RATE, 2, None, np.zeros(4)) == "" for k in range(1, 10))


def test_a_certificate_with_a_declared_disturbance_holds_on_manoeuvring_bodies(paper, ktable):
    """``e0`` unknown, every velocity driven by a bang-bang acceleration of 0.2 m/s^2 within the
    declared disturbance: the window's certificate counts what the disturbance moved the state
    over the window (the reach of ``(-A, B_w)``), so the bound it restarts holds at every sample
    from then on (at most 0.25 of it here; at 2 m/s^2 0.31, where without the hook every window
    is refused: the data do not fit the undisturbed model)."""
    from switchobs_core.model.disturbance import Disturbance, velocity_inputs
    from switchobs_core.runtime.recovery import window_disturbance
    from switchobs_core.sim.disturbed import bang_bang
    from switchobs_core.sim.plant import Plant

    dist = Disturbance(velocity_inputs(paper), 0.2)
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0 + 3.0, e0=None, noise_max=VMAX,
                           disturbance=dist)
    hook = window_disturbance(obs)
    assert hook is not None and hook(0.0, 1) == 0.0 and 0 < hook(-0.5, 1) < hook(-1.0, 1) < math.inf
    assert window_disturbance(SwitchedObserver(paper, ktable, "periodic", [CYC], e0=None, noise_max=VMAX)) is None
    rec = Recovery(obs)
    sched = PeriodicSchedule(CYC)
    rng = np.random.default_rng(4)
    plant = Plant(paper, X0, B_w=dist.B_w)
    w = bang_bang(dist.w_max, RATE, seed=5)
    first, worst = None, 0.0
    for k in range(int(5 * RATE) + 1):
        t = k / RATE
        x = plant.advance(t, w=w((k - 1) / RATE) if k else None)
        c = sched.channel_at(t)
        y = paper.C[c - 1] @ x + rng.uniform(-VMAX, VMAX, 4)
        rec.before(t, c, None, y)
        obs.update(t, c, y)
        if rec.after(t, c, None, y, first is not None) is not None and first is None:
            first = t
        nb = obs.envelope().noise_bound
        if first is not None:
            worst = max(worst, np.linalg.norm(obs.x_hat - x) / nb)
    assert first is not None and first <= 2.0 + 1e-9
    assert worst <= 1.0, worst


def _noise_free_run(paper, ktable, bias_at=None):
    """4 s of noise-free samples, e0 unknown, noise_max 0; ``bias_at``: from that time on, +-1e-6 of
    alternating sign on the camera's x row (no trajectory of the model reads so). Returns the time of
    the first certificate, the final error and bound, and the recovery."""
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0 + 3.0, e0=None, noise_max=0.0)
    rec = Recovery(obs, bias=False)
    first = None
    for k, t, c, x in _paper_samples(paper, 4.0):
        y = paper.C[c - 1] @ x
        if bias_at is not None and t >= bias_at:
            y = y + np.array([1e-6 * (-1) ** k, 0, 0, 0])
        obs.update(t, c, y)
        if rec.after(t, c, None, y, first is not None) is not None:
            first = t
        if first is not None:
            assert np.linalg.norm(obs.x_hat - x) <= obs.envelope().noise_bound
    return first, np.linalg.norm(obs.x_hat - x), obs.envelope().noise_bound, rec


def test_a_noise_free_declaration_certifies_a_rounding_level_bound(paper, ktable):
    """noise_max 0: a cycle of exact samples (the plant in double) certifies a bound at the rounding
    level (the allowance NOISE_FREE of each sample's largest entry), which holds from then on."""
    first, err, bound, rec = _noise_free_run(paper, ktable)
    assert first == 2.0 and rec.recertifications == 1
    assert err <= bound < 1e-5 * np.linalg.norm(X0)


def test_a_noise_free_window_with_micrometre_noise_is_refused(paper, ktable):
    """noise_max 0: samples 1e-6 off the model (noise far above the rounding level) never certify."""
    first, _, bound, rec = _noise_free_run(paper, ktable, bias_at=0.0)
    assert first is None and math.isinf(bound) and rec.window.refused > 0


def test_the_bias_test_on_the_prior_handed_over_is_the_one_it_asks_for(paper, ktable):
    """``before(..., x_p)`` with the prediction of ``prior(t)`` (as the screening hands it over), and with the
    innovation test's innovation too, keeps the CUSUM's statistics and alarms of ``before`` asking
    ``predict(t, hold=True)`` itself, bit for bit, through a bias that alarms."""
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=X0 + 0.05, e0=5.0, noise_max=VMAX)
    asks, handed, shared, quiet = Recovery(obs), Recovery(obs), Recovery(obs), Recovery(obs)
    test = InnovationTest(obs.C, obs.noise_max)
    rng = np.random.default_rng(3)
    alarms = 0
    for k, t, c, x in _paper_samples(paper, 6.0):
        y = paper.C[c - 1] @ x + rng.uniform(-VMAX, VMAX, paper.C[c - 1].shape[0]) + (0.05 if k > 150 else 0.0)
        with np.errstate(all="ignore"):
            prior = obs.prior(t, lazy=True)
        why = asks.before(t, c, None, y)
        assert handed.before(t, c, None, y, prior[0]) == why
        assert shared.before(t, c, None, y, prior[0], test.check(prior, c, None, y).nu) == why
        with np.errstate(all="ignore"):     # the screening's: the caller's error state, none of its own
            assert quiet.before(t, c, None, y, prior[0], test.check(prior, c, None, y).nu, quiet=True) == why
        alarms += bool(why)
        for g in ("g_pos", "g_neg"):
            for a, b, d, q in zip(getattr(asks.bias, g), getattr(handed.bias, g), getattr(shared.bias, g),
                                  getattr(quiet.bias, g), strict=True):
                np.testing.assert_array_equal(a, b, strict=True)
                np.testing.assert_array_equal(a, d, strict=True)
                np.testing.assert_array_equal(a, q, strict=True)
        obs.update(t, c, y)
    assert alarms > 0       # the bias was seen: the alarms' path ran in both
