"""Tests of switchobs_core.runtime.observer.SwitchedObserver."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _paper_designs import NONPERIODIC, PERIODIC, paper_table
from _sampled_reference import sampled_reference
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from switchobs_core.bounds.envelope import schedule_segments
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.schedule import PeriodicSchedule, SequenceSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.sim.simulate import designs_for, simulate


@pytest.fixture(scope="module")
def table(paper):
    return paper_table(paper, robust=(0.8, 1.2))


def _zoh(M, w, x, dt):
    """Independent ZOH step: x(dt) = e^{M dt} x + int_0^dt e^{M s} ds w (series-free, via expm of 2n)."""
    n = M.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = M, w
    E = expm(aug * dt)
    return E[:n, :n] @ x + E[:n, n]


def test_single_steps_match_independent_zoh(paper, table):
    """Measurement hold: the literal ZOH of e:switched_observer."""
    d = table.lookup(PERIODIC)
    rng = np.random.default_rng(0)
    x0 = rng.standard_normal(12)
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC], x0=x0, hold="measurement")
    y1, y2 = rng.standard_normal(4), rng.standard_normal(4)
    # before the first sample: open loop
    x = obs.update(0.05, 1, y1).copy()
    np.testing.assert_allclose(x, expm(paper.A * 0.05) @ x0, rtol=1e-12, atol=1e-14)
    # then channel-1 gain with y1 held
    M1 = paper.A - d.L[0] @ paper.C[0]
    x_exp = _zoh(M1, d.L[0] @ y1, x, 0.07)
    np.testing.assert_allclose(obs.update(0.12, 2, y2), x_exp, rtol=1e-11, atol=1e-13)
    # partial rows of channel 2 (target rows only): columns 2, 3 of L_2
    M2 = paper.A - d.L[1][:, 2:] @ paper.C[1][2:, :]
    x_exp2 = _zoh(paper.A - d.L[1] @ paper.C[1], d.L[1] @ y2, x_exp, 0.03)
    x2 = obs.update(0.15, 2, y2[2:], rows=[2, 3]).copy()
    np.testing.assert_allclose(x2, x_exp2, rtol=1e-11, atol=1e-13)
    x_exp3 = _zoh(M2, d.L[1][:, 2:] @ y2[2:], x_exp2, 0.04)
    np.testing.assert_allclose(obs.update(0.19, 2, y2), x_exp3, rtol=1e-11, atol=1e-13)


def test_single_steps_innovation_hold(paper, table):
    """Innovation hold: x+ = e^{A dt} x + Gamma_A L (y - C x(t_k)), by an independent expm."""
    d = table.lookup(PERIODIC)
    rng = np.random.default_rng(4)
    x0 = rng.standard_normal(12)
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC], x0=x0)
    y1, y2 = rng.standard_normal(4), rng.standard_normal(4)
    x = obs.update(0.05, 1, y1).copy()
    np.testing.assert_allclose(x, expm(paper.A * 0.05) @ x0, rtol=1e-12, atol=1e-14)
    nu = y1 - paper.C[0] @ x
    x_exp = _zoh(paper.A, d.L[0] @ nu, x, 0.07)
    np.testing.assert_allclose(obs.update(0.12, 2, y2), x_exp, rtol=1e-11, atol=1e-13)
    # partial rows: the innovation of the given rows only, with the matching columns of L_2
    nu2 = y2 - paper.C[1] @ x_exp
    x_exp2 = _zoh(paper.A, d.L[1] @ nu2, x_exp, 0.03)
    x2 = obs.update(0.15, 2, y2[2:], rows=[2, 3]).copy()
    np.testing.assert_allclose(x2, x_exp2, rtol=1e-11, atol=1e-13)
    nu3 = y2[2:] - paper.C[1][2:, :] @ x_exp2
    np.testing.assert_allclose(obs.update(0.19, 2, y2), _zoh(paper.A, d.L[1][:, 2:] @ nu3, x_exp2, 0.04),
                               rtol=1e-11, atol=1e-13)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), worst=st.booleans())
def test_innovation_hold_exact_bound_is_exact_for_samples(paper, table, seed, worst):
    """Property: with innovation hold the error obeys x_tilde(t) = Phi(t, 0) x_tilde(0) exactly for
    noiseless samples of a moving, unstable plant (random plant state, random initial error): the
    true error never exceeds the exact bound, and in the worst direction (top right singular vector
    of the final Phi) it attains it."""
    rng = np.random.default_rng(seed)
    x0 = 5.0 * rng.standard_normal(12)  # a large, fast plant state
    e = 0.1 * rng.standard_normal(12)
    if worst:
        probe = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
        samp = simulate(paper, table, PeriodicSchedule(PERIODIC), x0, x0, 6.0, rate=100.0)
        for k, tk in enumerate(samp.t):
            probe.update(float(tk), int(samp.channel[k]), samp.y[k])
        e = 0.1 * np.linalg.svd(probe.Phi)[2][0]
    res = simulate(paper, table, PeriodicSchedule(PERIODIC), x0, x0 + e, 6.0, rate=100.0)
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC], x0=x0 + e,
                           e0=float(np.linalg.norm(e)))
    for k, tk in enumerate(res.t):
        obs.update(float(tk), int(res.channel[k]), res.y[k])
        err = obs.x_hat - res.x[k]
        np.testing.assert_allclose(err, obs.Phi @ e, rtol=1e-8, atol=1e-11)
        assert np.linalg.norm(err) <= obs.envelope().exact_bound * (1 + 1e-9)
    if worst:   # attained, up to the bound's allowance for rounding (relative ~1e-8 here)
        assert np.linalg.norm(err) == pytest.approx(obs.envelope().exact_bound, rel=1e-6)
        assert np.linalg.norm(err) <= obs.envelope().exact_bound


@pytest.mark.parametrize("hold", ["innovation", "measurement"])
def test_observer_matches_simulator_to_1e9(paper, table, hold):
    rng = np.random.default_rng(7)
    x0 = rng.standard_normal(12)
    e = 0.1 * rng.standard_normal(12)
    sched = SequenceSchedule(NONPERIODIC)
    # an independent implementation (simulate() itself runs SwitchedObserver)
    _, designs = designs_for(table, sched)
    segs = schedule_segments(sched, designs, 14.0)
    t, x_hat, channel, ys = sampled_reference(paper.A, np.zeros((12, 0)), paper.C, segs, x0, x0 + e, 0.0, 14.0,
                                              50.0, 0.01, 3, hold)
    obs = SwitchedObserver(paper, table, mode="sequence", cycles=NONPERIODIC, x0=x0 + e, hold=hold)
    worst = 0.0
    for k, tk in enumerate(t):
        y = ys[k]  # the simulator's noisy sample
        worst = max(worst, float(np.max(np.abs(obs.update(float(tk), int(channel[k]), y) - x_hat[k]))))
    assert worst < 1e-9
    # cycle bookkeeping: the sequence's designs were used in order
    recs = obs.completed_cycles
    assert [r.design_index for r in recs[:4]] == [0, 1, 2, 3]
    assert all(r.matched for r in recs)


def test_cycle_records_and_paper_factors(paper, table):
    d = table.lookup(PERIODIC)
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    # cycle 0: channel 1 for 1.3 s, channel 2 for 0.8 s; cycle 1: the promised (1.2, 0.8)
    for t, ch in [(0.0, 1), (0.5, 1), (1.3, 2), (2.0, 2), (2.1, 1), (3.3, 2), (4.1, 1)]:
        obs.update(t, ch, np.zeros(4))
    r0, r1 = obs.completed_cycles
    assert r0.tau == pytest.approx(2.1) and r0.h == pytest.approx((1.3, 0.8)) and r0.s == pytest.approx(1.3 / 2.1)
    f_exp = tuple(d.kappa[i] * math.exp(d.mu[i] * (2.1 - r0.h[i]) - d.eta[i] * r0.h[i]) for i in range(2))
    assert r0.f == pytest.approx(f_exp, rel=1e-12)
    assert r0.matched is False and r0.order == (1, 2)
    assert r1.h == pytest.approx((1.2, 0.8)) and r1.matched is True
    assert r1.f == pytest.approx(d.f, rel=1e-9)
    assert obs.current_design is d


def test_robust_mode_checks_a2(paper, table):
    obs = SwitchedObserver(paper, table, mode="robust")
    assert obs.bounds == (0.8, 1.2)
    for t, ch in [(0.0, 1), (1.0, 2), (2.1, 1), (2.6, 2), (3.6, 1)]:
        obs.update(t, ch, np.zeros(4))
    r0, r1 = obs.completed_cycles
    assert r0.a2_ok is True and r0.matched is True
    assert r1.a2_ok is False and r1.matched is False  # h_1 = 0.5 < h_min


def test_predict_and_envelope(paper, table):
    d = table.lookup(PERIODIC)
    rng = np.random.default_rng(2)
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC], e0=0.5, hold="measurement")
    y = rng.standard_normal(4)
    obs.update(0.0, 1, y)
    obs.update(0.4, 1, y)
    x = obs.x_hat
    np.testing.assert_allclose(obs.predict(0.9), expm(paper.A * 0.5) @ x, rtol=1e-12, atol=1e-14)
    held = obs.predict(0.9, hold=True)
    assert obs.t == 0.4 and np.array_equal(obs.x_hat, x)
    np.testing.assert_allclose(obs.update(0.9, 1, y), held, rtol=1e-13, atol=1e-15)
    obs.update(1.2, 2, y)
    env = obs.envelope()
    M1 = paper.A - d.L[0] @ paper.C[0]
    assert env.exact_bound == pytest.approx(np.linalg.norm(expm(M1 * 1.2), 2) * 0.5, rel=1e-10)
    z_exp = [d.kappa[0] * math.exp(-d.eta[0] * 1.2) * 0.5, d.kappa[1] * math.exp(d.mu[1] * 1.2) * 0.5]
    np.testing.assert_allclose(env.z, z_exp, rtol=1e-12)
    assert env.paper_bound == pytest.approx(obs.alpha * sum(z_exp), rel=1e-12)


def test_fixed_rate_hits_the_cache(paper, table):
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    for k in range(2000):
        t = k * 0.01
        obs.update(t, PeriodicSchedule(PERIODIC).channel_at(t), np.zeros(4))
    assert obs.cache.misses <= 4 and obs.cache.hits >= 1990
    assert len(obs.completed_cycles) == 9
    obs.reset()
    assert obs.t == 0.0 and obs.channel == 0 and obs.completed_cycles == []


@pytest.mark.parametrize("call,match", [
    (lambda o: o.update(-1.0, 1, np.zeros(4)), "earlier"),
    (lambda o: o.update(0.1, 3, np.zeros(4)), "channel"),
    (lambda o: o.update(0.1, 1, np.zeros(3)), "4 entries"),
    (lambda o: o.update(0.1, 1, [0, 0, np.nan, 0]), "non-finite"),
    (lambda o: o.update(0.1, 1, np.zeros(2), rows=[0, 7]), "rows"),
    (lambda o: o.update(float("nan"), 1, np.zeros(4)), "finite"),
    (lambda o: o.predict(-0.5), "t ="),
    (lambda o: o.update(0.1, 1, np.zeros(4), u=[1.0]), "u must"),
])
def test_update_rejects_bad_input(paper, table, call, match):
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    with pytest.raises(InvalidArgument, match=match):
        call(obs)


@pytest.mark.parametrize("kw,match", [
    ({"mode": "nope", "cycles": [PERIODIC]}, "mode"),
    ({"mode": "periodic", "cycles": None}, "cycles is required"),
    ({"mode": "periodic", "cycles": [PERIODIC, PERIODIC]}, "exactly one"),
    ({"mode": "periodic", "cycles": [PERIODIC], "x0": np.zeros(3)}, "x0"),
    ({"mode": "periodic", "cycles": [PERIODIC], "e0": -1}, "e0"),
])
def test_constructor_rejects_bad_arguments(paper, table, kw, match):
    with pytest.raises(InvalidArgument, match=match):
        SwitchedObserver(paper, table, **kw)


def test_sequence_mode_resyncs_after_a_late_start(paper, table):
    """Started 4 s into the paper's sequence (4,0.5),(3,0.6),(3,0.6),(2,0.4), the observer's
    cycle count is off by one; after mismatched cycles it finds its place in the sequence, and
    from then on every cycle is run with the gains designed for it."""
    sched = SequenceSchedule(NONPERIODIC)
    obs = SwitchedObserver(paper, table, mode="sequence", cycles=NONPERIODIC)
    for t in np.arange(4.0, 60.0, 0.01):
        obs.update(float(t), sched.channel_at(float(t) + 1e-9), np.zeros(4))
    recs = obs.completed_cycles
    assert not recs[0].matched and obs.resyncs >= 1
    first_ok = next(i for i, r in enumerate(recs) if r.matched)
    assert first_ok <= 3
    assert all(r.matched for r in recs[first_ok:])
    # the gains used are those of the cycle that was run
    for r in recs[first_ok:]:
        assert NONPERIODIC[r.design_index].matches(r.promised)
        assert r.h == pytest.approx(r.promised.h, abs=0.011)


@pytest.mark.parametrize("channel", [1.0, True, 0, 3, "1"])
def test_channel_must_be_an_integer_in_range(paper, table, channel):
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    obs.update(0.0, 1, np.zeros(4))
    with pytest.raises(InvalidArgument, match="channel must be an integer in 1..2"):
        obs.update(0.1, channel, np.zeros(4))


@pytest.mark.parametrize("y, match", [
    ([np.nan, 0, 0, 0], "non-finite entry"), ([0, -np.inf, 0, 0], "non-finite entry"),
    ([0, 0, 1e151, 0], "too large"), ([1e150, 1e150, 0, 0], "too large"),
])
def test_update_refuses_samples_that_would_overflow(paper, table, y, match):
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    obs.update(0.0, 1, np.zeros(4))
    with pytest.raises(InvalidArgument, match=match):
        obs.update(0.01, 1, np.array(y, dtype=float))
    obs.update(0.01, 1, np.array([1e149, 0.0, 0.0, -1e149]))  # large but representable: accepted


@pytest.mark.parametrize("y, match", [
    ([1e200, 1e200, 0, 0], r"too large \(\|\|y\|\| = 1.41e\+200"),   # y'y overflows: the message's norm does not
    ([1j, 0, 0, 0], "y must be real numbers"), ([2 ** 1100, 0, 0, 0], "y must be real numbers"),
    (["a", 0, 0, 0], "y must be real numbers"),
])
def test_update_refuses_samples_it_cannot_read_with_a_clear_error(paper, table, y, match):
    obs = SwitchedObserver(paper, table, mode="periodic", cycles=[PERIODIC])
    obs.update(0.0, 1, np.zeros(4))
    with pytest.raises(InvalidArgument, match=match):
        obs.update(0.01, 1, y)
    assert np.all(np.isfinite(obs.update(0.02, 1, np.zeros(4))))      # the observer goes on


@settings(max_examples=200, deadline=None)
@given(q=st.integers(1, 40), scale=st.sampled_from([1.0, 1e100, 1e149, 1e150, 1e151, 1e200, 1e300]),
       seed=st.integers(0, 2**32 - 1))
def test_sample_size_check_matches_the_norm_at_any_length(q, scale, seed):
    """:func:`check_sample` accepts ``y`` exactly when ``||y|| <= MAX_ABS_SAMPLE`` (up to the norm's
    rounding), on both of its paths (a few entries and many), without a warning."""
    import warnings
    from fractions import Fraction

    from switchobs_core.runtime.arguments import MAX_ABS_SAMPLE, check_sample

    y = np.random.default_rng(seed).standard_normal(q) * scale / math.sqrt(q)
    exact_sq = sum(Fraction(v) ** 2 for v in y.tolist())
    limit_sq = Fraction(MAX_ABS_SAMPLE) ** 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            check_sample(1.0, 0.0, 1, y, None, None, (q,), 0)
            accepted = True
        except InvalidArgument as exc:
            assert "too large" in str(exc)
            accepted = False
    if abs(exact_sq / limit_sq - 1) > Fraction(1, 10**12):       # away from the bound's rounding
        assert accepted == (exact_sq <= limit_sq)
