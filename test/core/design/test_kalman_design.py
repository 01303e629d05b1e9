"""Offline periodic Kalman gains vs the online filter, the periodic Riccati equation, the lifted
DARE, detectability, lookup, persistence, Joseph-form properties and a Monte Carlo NEES test."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from switchobs_core.design.kalman import design_kalman, sample_pattern
from switchobs_core.design.riccati import DiscretizationCache, Step, discretize, lifted_dare, periodic_riccati
from switchobs_core.exceptions import KalmanDesignError, RiccatiError, SwitchobsError, UndetectableSchedule
from switchobs_core.model.noise import NoiseModel, default_noise
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.model.system import LTISystem
from switchobs_core.numerics.kalman_step import joseph, riccati_step
from switchobs_core.numerics.propagation import (
    COMPOSE_GRID,
    DEFAULT_DT_RESOLUTION,
    quantize_dt,
    split_step,
    taylor_pair,
    van_loan,
)
from switchobs_core.runtime.kalman_online import OnlineKalman
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.table.gains import kalman_table
from switchobs_core.table.kalman import KalmanDesign

PAPER = paper_system()
CYC = Cycle.from_ts(2.0, 0.6)
RATE = 50.0


@pytest.fixture(scope="module")
def design():
    return design_kalman(PAPER, CYC, RATE, default_noise(PAPER))


def _rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("cycle, stamps", [(CYC, "pattern"), (Cycle.from_ts(2.0, 0.605), "channel_at")])
def test_offline_gains_equal_online_gains(cycle, stamps):
    """On a drop-free nominal stream the table's gain equals the online Riccati gain at every sample,
    through the start-up and 5 periods beyond (stamps as camera_sim makes them: k * period_ns)."""
    d = design_kalman(PAPER, cycle, RATE)
    sch = PeriodicSchedule(cycle)
    on = OnlineKalman(PAPER, d.noise)
    n_samples = len(d.startup) + 5 * d.pattern.K
    worst = 0.0
    for k in range(n_samples):
        t = k * round(1e9 / RATE) * 1e-9
        ch = d.pattern.channels[k % d.pattern.K] if stamps == "pattern" else sch.channel_at(t)
        on.update(t, ch, np.zeros(4))
        ph = d.phase_at(t)
        assert ph.startup == (k < len(d.startup))
        worst = max(worst, _rel(d.gain(ph, ch), on.K))
    assert worst <= 1e-9
    assert len(d.startup) > d.pattern.K  # the start-up is really exercised


def test_periodic_solution_is_a_fixed_point(design):
    """One period of the recursion from the stored prior of phase 0 reproduces every stored prior."""
    Phi, _, Qd = discretize(PAPER.A, PAPER.B, design.noise.Q_c, 1 / RATE)
    P = design.periodic[0].P_prior
    for k in range(1, design.pattern.K + 1):
        e = design.periodic[(k - 1) % design.pattern.K]
        _, Pp = riccati_step(P, PAPER.C[e.channel - 1], design.noise.R(e.channel))
        P = Phi @ Pp @ Phi.T + Qd
        assert _rel(P, design.periodic[k % design.pattern.K].P_prior) <= 1e-10
    # and the period's error transition is a contraction (rho < 1), its norm >= its radius
    assert 0 < design.rho < 1 and design.norm >= design.rho


def test_lifted_dare_cross_check():
    """The periodic priors equal the block diagonal of the cyclically lifted DARE's solution."""
    A = np.array([[0, 1, 0, 0], [0, -0.1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0.05]], dtype=float)
    sysm = LTISystem(A, None, [np.array([[1.0, 0, 0, 0]]), np.array([[1.0, 0, -1, 0]])])
    noise = NoiseModel.for_system(sysm, measurement_std=[0.1, 0.05], process_std=0.3, P0=2.0)
    d = design_kalman(sysm, Cycle((0.3, 0.2)), 10.0, noise)
    assert d.pattern.channels == (1, 1, 1, 2, 2)
    Phi, _, Qd = discretize(A, sysm.B, noise.Q_c, 0.1)
    steps = [Step(Phi, Qd, sysm.C[c - 1], noise.R(c)) for c in d.pattern.channels]
    lifted = lifted_dare(steps)
    for k, Pl in enumerate(lifted):
        assert _rel(d.periodic[k].P_prior, Pl) <= 1e-8


def test_undetectable_schedule_names_channel_and_mode():
    """At 10 Hz no sample falls in channel 2's 80 ms window of h = (1.02, 0.08): agent 2 is never seen."""
    with pytest.raises(UndetectableSchedule, match=r"not detectable.*agent2\.p_[xy].*Channel\(s\) \[2\] get no sample"):
        design_kalman(PAPER, Cycle((1.02, 0.08)), 10.0)


def test_unseen_agent_in_three_agent_system():
    sysm = camera_agents(3)
    with pytest.raises(UndetectableSchedule, match=r"agent3.*Channel\(s\) \[3\]"):
        design_kalman(sysm, Cycle((0.5, 0.55, 0.05)), 10.0)


def test_non_integral_period_and_lcm():
    with pytest.raises(KalmanDesignError, match=r"T f = 100.65 samples, not a whole number"):
        sample_pattern(Cycle.from_ts(2.013, 0.6), RATE, max_repeat=10)
    p = sample_pattern(Cycle.from_ts(2.05, 0.6), 30.0)  # 61.5 samples per cycle: two cycles per period
    assert p.repeat == 2 and p.K == 123


def test_ties_are_listed_and_served_from_the_stored_prior(design):
    """The sample at the switching instant 1.2 s is a tie; served on the other channel its gain is
    P^- H' (H P^- H' + R)^-1 of that channel from the stored prior."""
    assert design.pattern.ties == (60,)
    ph = design.phase_at(1000 * 2.0 + 1.2)
    assert not ph.startup and ph.index == 60 and design.entry(ph).channel == 2
    K1 = design.gain(ph, 1)
    P, H, R = design.entry(ph).P_prior, PAPER.C[0], design.noise.R(1)
    assert np.allclose(K1, P @ H.T @ np.linalg.inv(H @ P @ H.T + R), rtol=1e-10, atol=0)


def test_phase_lookup(design):
    S, K = len(design.startup), design.pattern.K
    assert design.phase_at(0.0).startup and design.phase_at(0.0).index == 0
    ph = design.phase_at((S + 3) / RATE + 2e-3)  # 0.1 sample of jitter
    assert not ph.startup and ph.index == (S + 3) % K and abs(ph.offset - 2e-3) < 1e-12
    with pytest.raises(ValueError, match="sample periods off the 50 Hz grid"):
        design.phase_at(0.01)
    with pytest.raises(ValueError, match="t must be a finite time >= 0"):
        design.phase_at(-1.0)


def test_round_trip_exact(design):
    d2 = KalmanDesign.from_dict(json.loads(json.dumps(design.to_dict())), PAPER)
    for a, b in zip(design.periodic + design.startup, d2.periodic + d2.startup):
        assert a.channel == b.channel and a.dt == b.dt
        assert np.array_equal(a.P_prior, b.P_prior) and np.array_equal(a.K, b.K)
    assert d2.noise.fingerprint() == design.noise.fingerprint() and d2.pattern == design.pattern
    with pytest.raises(KalmanDesignError, match="made for another system"):
        KalmanDesign.from_dict(design.to_dict(), camera_agents(2, D_agents=[(0, 0.3), (0, 0.1)]))


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 8),
    p=st.integers(1, 4),
    optimal=st.booleans(),
)
def test_joseph_symmetric_psd(seed, n, p, optimal):
    """The Joseph form returns an exactly symmetric PSD matrix, for the optimal gain and for any gain."""
    rng = np.random.default_rng(seed)
    L = rng.standard_normal((n, n)) * 10 ** rng.uniform(-3, 3)
    P = L @ L.T
    H = rng.standard_normal((p, n))
    R = np.diag(10 ** rng.uniform(-6, 0, p))
    K = riccati_step(P, H, R)[0] if optimal else rng.standard_normal((n, p)) * 10 ** rng.uniform(-2, 2)
    Pp = joseph(P, K, H, R)
    assert np.array_equal(Pp, Pp.T)
    assert np.linalg.eigvalsh(Pp)[0] >= -1e-12 * np.linalg.norm(Pp, 2)
    if optimal:  # the optimal correction never increases the covariance
        assert np.linalg.eigvalsh(P - Pp)[0] >= -1e-9 * np.linalg.norm(P, 2)


def test_periodic_riccati_reports_non_convergence():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    Phi, _, _ = discretize(A, np.zeros((2, 0)), np.zeros((2, 2)), 0.1)
    steps = [Step(Phi, np.zeros((2, 2)), np.array([[1.0, 0.0]]), np.array([[1e-2]]))]
    with pytest.raises(RiccatiError, match="did not converge in 50 periods.*increase Q_c"):
        periodic_riccati(steps, np.eye(2), max_periods=50)


def _simulate(design, runs, n_samples, seed, drop=0.0, channel_at=False):
    """Plant with exactly the declared noise (van Loan Q_d, R per row), all runs at once."""
    rng = np.random.default_rng(seed)
    noise, sysm = design.noise, design.system
    n = sysm.n
    F, Qd = van_loan(sysm.A, noise.Q_c, 1 / RATE)
    Lq = np.linalg.cholesky(Qd)
    x = np.linalg.cholesky(noise.P0) @ rng.standard_normal((n, runs))  # x_hat0 = 0, x0 ~ N(0, P0)
    sch = PeriodicSchedule(CYC)
    for k in range(n_samples):
        if k:
            x = F @ x + Lq @ rng.standard_normal((n, runs))
        t = k * round(1e9 / RATE) * 1e-9
        ch = sch.channel_at(t) if channel_at else design.pattern.channels[k % design.pattern.K]
        rows = [0, 1] if rng.uniform() < drop else None
        H = sysm.C[ch - 1] if rows is None else sysm.C[ch - 1][rows]
        std = np.sqrt(np.diag(noise.R(ch, rows)))
        y = H @ x + std[:, None] * rng.standard_normal((H.shape[0], runs))
        yield k, t, ch, rows, x, y


def test_monte_carlo_nees_in_chi2_band(design):
    """Average NEES over 200 seeded runs lies in the chi-square 95 % band, in the start-up and periodic."""
    runs, n = 200, PAPER.n
    checks = {40: None, len(design.startup) + 37: None}
    xh = np.zeros((n, runs))
    F = van_loan(PAPER.A, design.noise.Q_c, 1 / RATE)[0]
    for k, t, ch, _, x, y in _simulate(design, runs, max(checks) + 1, seed=7):
        if k:
            xh = F @ xh
        ph = design.phase_at(t)
        K = design.gain(ph, ch)
        xh = xh + K @ (y - PAPER.C[ch - 1] @ xh)
        if k in checks:
            e = x - xh
            Pinv = np.linalg.inv(design.posterior(ph, ch))
            checks[k] = float(np.mean(np.einsum("ir,ij,jr->r", e, Pinv, e)))
    lo, hi = chi2.ppf([0.025, 0.975], runs * n) / runs
    for k, nees in checks.items():
        assert lo <= nees <= hi, (k, nees, lo, hi)


def test_table_observer_with_drops_close_to_online():
    """2 % dropped target rows and the simulator's channel rule over 266 s (the tie sample 1.2 s into
    a cycle stays on the new channel all along: the schedule's tie rule, which the design used too):
    the observer with the Kalman table (the stored gains while the samples follow the pattern, the
    recursion online from a dropped row until its prior is the table's again) has an RMS error
    within 5 % of the online filter's. Agents with stable velocity modes, so that the plant state
    stays of moderate size over the long run (the paper's unstable agents grow by e^{0.2 t}, and
    the error would drown in the rounding of a 1e23 m state)."""
    sysm = camera_agents(2, D_agents=[(0.0, -0.2), (0.0, -0.1)])
    design = design_kalman(sysm, CYC, RATE)
    obs = SwitchedObserver(sysm, kalman_table(sysm, [design]), cycles=[CYC], rounding_bound=False)
    on = OnlineKalman(sysm, design.noise)
    err_t, err_o = [], []
    drops = flips = from_table = 0
    for k, t, ch, rows, x, y in _simulate(design, 1, 13300, seed=3, drop=0.02, channel_at=True):
        drops += rows is not None
        flips += ch != design.pattern.channels[k % design.pattern.K]
        obs.update(t, ch, y[:, 0], rows=rows)
        on.update(t, ch, y[:, 0], rows)
        from_table += obs.gains_source == "table"
        if t >= 2.0:
            err_t.append(x[:, 0] - obs.x_hat)
            err_o.append(x[:, 0] - on.x)
    rms_t, rms_o = (float(np.sqrt(np.mean(np.square(e)))) for e in (err_t, err_o))
    assert drops >= 150 and flips == 0
    assert rms_t <= 1.05 * rms_o
    # the drops left the table (about 240 times here), the observer came back to it after
    # each, and the table served most samples (85 % here)
    assert obs.kalman_departures >= 100 and obs.kalman_relocks >= obs.kalman_departures - 1
    assert from_table >= 0.8 * 13300


def test_partial_rows_gain_and_posterior(design):
    """A dropped target pose: K_r = P^- H_r' (H_r P^- H_r' + R_r)^-1 from the stored prior, and the
    Joseph posterior with it is larger than the full-sample posterior."""
    ph = design.phase_at(30 * 2.0 + 0.5)
    e = design.entry(ph)
    Kr = design.gain(ph, rows=[0, 1])
    H, R = PAPER.C[e.channel - 1][[0, 1]], design.noise.R(e.channel, [0, 1])
    assert np.allclose(Kr, e.P_prior @ H.T @ np.linalg.inv(H @ e.P_prior @ H.T + R), rtol=1e-10, atol=0)
    assert design.gain(ph, rows=[0, 1, 2, 3]) is e.K
    gap = design.posterior(ph, rows=[0, 1]) - design.posterior(ph)
    assert np.linalg.eigvalsh(gap)[0] >= -1e-15 and np.trace(gap) > 0


@pytest.mark.parametrize(
    "call, exc, match",
    [
        (lambda: design_kalman(PAPER, CYC, -50.0), ValueError, "rate must be a finite number > 0"),
        (lambda: design_kalman(PAPER, CYC, True), ValueError, "rate must be a finite number > 0"),
        (lambda: design_kalman(PAPER, [], 50.0), ValueError, "non-empty list of Cycles"),
        (lambda: design_kalman(PAPER, CYC, 50.0, noise=1e-3), ValueError, "noise must be a NoiseModel"),
        (lambda: design_kalman(PAPER, CYC, 50.0, default_noise(camera_agents(3))), ValueError,
         "noise model is for n = 16"),
        (lambda: OnlineKalman(PAPER, "x"), ValueError, "noise must be a NoiseModel"),
    ],
)
def test_bad_arguments(call, exc, match):
    with pytest.raises(exc, match=match) as err:
        call()
    assert isinstance(err.value, SwitchobsError)


def test_online_filter_refuses_time_going_back():
    f = OnlineKalman(PAPER)
    f.update(1.0, 1, np.zeros(4))
    with pytest.raises(ValueError, match="before the previous sample"):
        f.update(0.5, 2, np.zeros(4))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(1e-4, 0.05), min_size=1, max_size=8), st.integers(0, 2**31 - 1))
def test_jittered_discretization_keeps_its_doubles(dts, seed):
    """The composed (jittered) step's third-order ``Q_d(r)`` uses two constant matrices computed
    once per cache; every step gives the same doubles as the formula written out per step, and
    stays within 1e-12 (relative) of the exact van Loan discretisation."""
    A = paper_system().A
    Qc = np.diag(np.random.default_rng(seed).uniform(1e-6, 1e-2, A.shape[0]))
    cache = DiscretizationCache(A, np.zeros((A.shape[0], 0)), Qc)
    for dt in dts:
        _, _, Qd = cache.get(dt)
        dtq = quantize_dt(dt, DEFAULT_DT_RESOLUTION)
        qc, r = split_step(dtq, DEFAULT_DT_RESOLUTION)
        if qc > 0 and r > 0:
            Phi_a, _, Qd_a = discretize(A, np.zeros((A.shape[0], 0)), Qc, qc * COMPOSE_GRID)
            Ps, _ = taylor_pair(A, r)
            AQ = A @ Qc
            Qd_r = Qc * r + (AQ + AQ.T) * (r * r / 2) + (A @ AQ + 2 * AQ @ A.T + (A @ AQ).T) * (r ** 3 / 6)
            Q = Ps @ Qd_a @ Ps.T + Qd_r
            assert np.array_equal(Qd, 0.5 * (Q + Q.T))
        _, Qd_exact = van_loan(A, Qc, dtq)
        assert np.linalg.norm(Qd - Qd_exact) <= 1e-12 * np.linalg.norm(Qd_exact)
