"""The ``kalman-online`` family's square-root recursion: the Joseph form's numbers on random systems
and stamps, positive definite where the covariance form is not, and a recursion out of digits
that says so and keeps answering."""

from __future__ import annotations

import numpy as np
import pytest
from _systems import stiff_pair
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg.lapack import dtrcon

import switchobs_core as so
from switchobs_core.exceptions import RiccatiError
from switchobs_core.model.noise import NoiseModel
from switchobs_core.numerics.kalman_step import compress_factor
from switchobs_core.runtime.families.base import Correction
from switchobs_core.runtime.kalman_online import OnlineKalman

_U = 2.0 ** -53


def _online(system, noise):
    """A ``kalman-online`` observer that needs no table (robust mode: no promised schedule)."""
    return so.SwitchedObserver(system, None, mode="robust", bounds=(0.1, 100.0), family="kalman-online",
                               noise=noise, rounding_bound=False)


def _rcond(obs) -> float:
    """LAPACK's estimate of the reciprocal condition of the recursion's (compressed) factor."""
    L = np.tril(compress_factor(obs.gains.factor))
    return float(dtrcon(L, norm="1", uplo="L")[0])


@st.composite
def _systems(draw):
    n = draw(st.integers(2, 6))
    N = draw(st.integers(2, 3))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    A = rng.normal(scale=0.6, size=(n, n))
    C = [rng.normal(size=(int(rng.integers(1, 3)), n)) for _ in range(N)]
    C[0] = np.vstack([C[0], np.eye(n)])          # the stacked pair observable (A1)
    system = so.LTISystem(A, None, C, name="random")
    noise = NoiseModel.for_system(system, measurement_std=float(10 ** rng.uniform(-3, -1)),
                                  process_std=float(10 ** rng.uniform(-2, 0)), P0=10.0)
    stamps = np.concatenate([[0.0], np.cumsum(rng.uniform(1e-3, 0.2, size=79))])   # the first at t0
    channels = rng.integers(1, N + 1, size=80)
    data = [rng.normal(size=system.p[c - 1]) for c in channels]
    return system, noise, stamps, channels, data


@settings(max_examples=40, deadline=None)
@given(_systems())
def test_square_root_recursion_gives_the_joseph_forms_numbers(case):
    """On random systems, channels and stamps (80 samples, steps 1-200 ms) the estimate and the
    covariance equal the Joseph form's (the standalone filter of runtime/kalman_online.py) within
    1e-8 relative: an equivalent formula, rounded differently, and each filter its own
    discretisation, which random unstable systems amplify (at most 9e-10 for the estimate and
    1.1e-10 for the covariance in 200 draws; the paper's model: 2.4e-14)."""
    system, noise, stamps, channels, data = case
    obs, ref = _online(system, noise), OnlineKalman(system, noise)
    for t, c, y in zip(stamps, channels, data):
        x = obs.update(float(t), int(c), y)
        xr = ref.update(float(t), int(c), y)
        P = obs.P
        assert np.linalg.norm(x - xr) <= 1e-8 * max(np.linalg.norm(xr), 1.0)
        assert np.linalg.norm(P - ref.P, 2) <= 1e-8 * np.linalg.norm(ref.P, 2)
        np.linalg.cholesky(P)                     # symmetric positive definite


@pytest.mark.slow
def test_long_stiff_run_stays_positive_definite():
    """20 000 samples of the stiff system at random stamps (1-20 ms apart, random channels): every
    covariance is symmetric positive definite (Cholesky), the factor keeps its digits, and the
    estimate still equals the Joseph form's within 1e-9."""
    system, noise = stiff_pair()
    rng = np.random.default_rng(11)
    obs, ref = _online(system, noise), OnlineKalman(system, noise)
    t = 0.0
    for k in range(20_000):
        t += float(rng.uniform(1e-3, 2e-2)) if k else 0.0      # the first sample at t0, as the reference starts
        c = int(rng.integers(1, 3))
        y = rng.normal(scale=1e-3, size=2)
        x, xr = obs.update(t, c, y), ref.update(t, c, y)
        P = obs.P
        assert np.array_equal(P, P.T)
        np.linalg.cholesky(P)
        if k % 1000 == 999:
            assert _rcond(obs) > 1e3 * 6 * _U
            assert np.linalg.norm(x - xr) <= 1e-9 * max(np.linalg.norm(xr), 1.0)


def _unseen_agent(d: float):
    """The camera model with agent 1's velocity mode ``d`` and agent 1 unseen 30 s of every 31 s."""
    system = so.camera_agents(2, D_agents=[(0.0, d), (0.0, 0.05)])
    return system, so.default_noise(system), so.PeriodicSchedule(so.Cycle((1.0, 30.0)))


def test_square_root_carries_a_covariance_the_joseph_form_cannot():
    """Agent 1 (0.9/s) unseen for 30 s: its covariance spans about 1e23, past the 16 digits of a
    double. The Joseph form's S = H P H' + R loses positive definiteness at the first view after
    the blind stretch (RiccatiError); the square-root recursion runs 5 periods with 1 ms stamp
    jitter, its factor nonsingular to working precision at every sample."""
    system, noise, sch = _unseen_agent(0.9)
    rng = np.random.default_rng(3)
    obs, ref = _online(system, noise), OnlineKalman(system, noise)
    failed = None
    worst = np.inf
    for k in range(5 * 310):
        t = k / 10.0 + (float(rng.uniform(-1e-3, 1e-3)) if k else 0.0)
        c = sch.channel_at(t)
        y = rng.normal(scale=1e-3, size=4)
        x = obs.update(t, c, y)
        assert np.all(np.isfinite(x))
        worst = min(worst, _rcond(obs))
        if failed is None:
            try:
                ref.update(t, c, y)
            except RiccatiError:
                failed = t
    assert failed is not None and 31.0 <= failed < 31.5
    assert worst >= 12 * _U
    d = np.linalg.eigvalsh(obs.P)
    assert d[-1] > 1e16 * 1e-6          # the covariance itself spans more than a double resolves


def test_recursion_out_of_digits_withdraws_the_covariance_and_keeps_answering():
    """Agent 1 at 1.2/s unseen for 30 s: even the factor runs out of digits (condition past
    1 / (n u)). The family restarts from P0 and returns its correction with the reason, one line
    naming the loss of positive definiteness; the observer answers every sample, its covariance
    is withdrawn with that reason until the reset, and the loss recurs once a period."""
    system, noise, sch = _unseen_agent(1.2)
    rng = np.random.default_rng(5)
    obs = _online(system, noise)
    lost, family_sample = [], obs.gains.sample

    def recording(s):
        c = family_sample(s)
        if c.lost:
            lost.append((s.t, c))
        return c

    obs.gains.sample = recording
    for k in range(3 * 310):
        t = k / 10.0
        x = obs.update(t, sch.channel_at(t), rng.normal(scale=1e-3, size=4))
        assert np.all(np.isfinite(x))
        assert (obs.P is None) == (len(lost) > 0)
    assert len(lost) == 3
    assert [round(t2 - t1, 6) for (t1, _), (t2, _) in zip(lost, lost[1:])] == [31.0, 31.0]
    why = lost[0][1].lost
    assert "\n" not in why and "lost positive definiteness" in why and "restarts from P0" in why
    assert obs.covariance_withdrawn == why and obs.prior_covariance(obs.t + 0.1) is None
    assert isinstance(lost[0][1], Correction) and np.all(np.isfinite(lost[0][1].x))
    assert _rcond(obs) > 12 * _U
    obs.reset()
    assert obs.covariance_withdrawn == "" and obs.P is not None
