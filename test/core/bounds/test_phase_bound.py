"""The observer's ``bound="phase"`` (switchobs_core.bounds.phase_bound): its published bounds against
the plant run in extended precision, over several periods of the table with a missing sample, a
restart, reads at a later time and a jittered step; its conversions to and from the ellipsoids
checked in exact rational arithmetic; and what it refuses."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from _extended_truth import Truth
from hypothesis import given, settings
from hypothesis import strategies as st
from test_audit import SYSTEMS
from test_phase_norm import _exact, _psd_exact, _spd

import switchobs_core as so
from switchobs_core.bounds.phase_bound import PhaseBound
from switchobs_core.bounds.phase_norm import PhaseNorms
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.disturbance import Disturbance

pytestmark = pytest.mark.skipif(np.finfo(np.longdouble).eps > 2.0**-60,
                                reason="needs an extended-precision longdouble (x86 80-bit or quad)")

LD = np.longdouble
NOISE_MAX = 1e-3
_TABLES: dict = {}


def _table(name: str, rate: float = 50.0) -> so.GainTable:
    if name not in _TABLES:
        system, cycle, _ = SYSTEMS[name]
        _TABLES[name] = so.kalman_table(system, [so.design_kalman(system, cycle, rate)])
    return _TABLES[name]


def run(name: str, seconds: float, *, noisy: bool, drop: int = -1, restart: int = -1, jitter: int = -1,
        later_every: int = 97, seed: int = 7, tolerance: float = 0.0, wobble: float = 0.0) -> dict:
    """The table observer with ``bound="phase"`` against the extended-precision plant: every
    sample's published bound (the noise bound with ``noisy``: the adversary's noise the sign of
    ``C e^-`` at ``NOISE_MAX``) and, every ``later_every`` samples, the bound read half a step later
    and the prior's set; ``drop`` a sample left out (a departure), ``restart`` a sample after which
    the bounds restart from the published bound (re-certification), ``jitter`` a sample moved by a
    third of a step, ``wobble`` a jitter of every stamp after the first, uniform within that many seconds (within
    the table's ``dt_tol``: no departure). Returns the worst ratio (error + 4 delta) / bound, the checks, the phase
    path's counts and the ellipsoid observer's bounds alongside.
    """
    system, cycle, x0 = SYSTEMS[name]
    rate = 50.0
    ts = [k / rate for k in range(int(seconds * rate) + 1)]
    grid = list(ts)         # the channel is the grid time's (a jittered stamp at a switch keeps its phase)
    if wobble:
        jit = np.random.default_rng(seed).uniform(-wobble, wobble, len(ts))
        ts = [ts[0]] + [t + float(w) for t, w in zip(ts[1:], jit[1:], strict=True)]
    if jitter > 0:
        ts[jitter] += 0.3 / rate
    if drop > 0:
        del ts[drop], grid[drop]
    sched = so.PeriodicSchedule(cycle)
    e0 = float(np.linalg.norm(x0)) * (1 + 1e-12)
    kw = {"e0": e0, "noise_max": NOISE_MAX if noisy else None}
    obs = so.SwitchedObserver(system, _table(name), "periodic", [cycle], bound="phase", **kw)
    ref = so.SwitchedObserver(system, _table(name), "periodic", [cycle], **kw)
    if tolerance:
        obs.rounding.clock(tolerance)
        ref.rounding.clock(tolerance)
    truth = Truth(system.A, x0)
    C = [np.asarray(Ci, dtype=LD) for Ci in system.C]
    out = {"worst": 0.0, "worst_on": 0.0, "checks": 0, "on": 0, "ratio": [], "later_on": 0}

    def check(xh: np.ndarray, x: np.ndarray, bound: float, on: bool = False) -> None:
        err = float(np.linalg.norm((np.asarray(xh, dtype=LD) - x).astype(float)))
        out["checks"] += 1
        out["worst"] = max(out["worst"], (err + 4 * truth.delta) / bound)
        if on:
            out["worst_on"] = max(out["worst_on"], (err + 4 * truth.delta) / bound)

    t_prev = 0.0
    pb = obs.rounding.phase
    for k, t in enumerate(ts):
        truth.advance(LD(t) - LD(t_prev))
        t_prev = t
        ch = sched.channel_at(grid[k])
        e_prior = (np.asarray(obs.predict(t, hold=True), dtype=LD) - truth.x).astype(float)
        v = NOISE_MAX * np.sign(system.C[ch - 1] @ e_prior) if noisy else np.zeros(system.p[ch - 1])
        if k % later_every == 50:       # the prior's set at the sample's time (before it)
            xp, S, Sv = obs.prior(t)        # norm bounds while the scalars hold, else ellipsoids
            S = Sv if noisy else S
            pb_on = pb.j >= 0
            out["later_on"] += pb_on
            check(xp, truth.x, float(S) if pb_on else math.sqrt(float(np.linalg.eigvalsh(0.5 * (S + S.T))[-1])
                                                                 * (1 + 1e-10)), pb_on)
        y = np.asarray(C[ch - 1] @ truth.x + np.asarray(v, dtype=LD), dtype=float)
        xh = obs.update(t, ch, y)
        assert np.array_equal(xh, ref.update(t, ch, y))     # the option changes the bound only
        env, er = obs.envelope(), ref.envelope()
        b, br = (env.noise_bound, er.noise_bound) if noisy else (env.exact_bound, er.exact_bound)
        check(xh, truth.x, b, pb.j >= 0)
        if pb.j >= 0:
            out["on"] += 1
            out["ratio"].append(b / br)
        if k == restart:
            obs.recertify(b)
            ref.recertify(br)
        if k % later_every == 0 and k + 1 < len(ts):
            tm = t + 0.5 * (ts[k + 1] - t)
            em = obs.envelope(tm)
            out["later_on"] += pb.j >= 0
            check(obs.predict(tm, hold=True), truth.at(LD(tm) - LD(t)), em.noise_bound if noisy else em.exact_bound,
                  pb.j >= 0)
    out.update(entered=pb.entered, left=pb.left, samples=len(ts), departures=obs.kalman_departures)
    return out


@pytest.mark.parametrize("name,seconds,noisy", [("osc", 18.0, False), ("osc", 18.0, True),
                                                ("agents10", 24.0, True), ("stiff", 6.0, False)])
def test_the_phase_bound_holds_against_the_plant_in_extended_precision(name, seconds, noisy):
    """Over several periods after the start-up, with a missing sample, a jittered step, a restart and
    reads at a later time: no published bound below the error (plus the truth's own 4 delta), the
    scalars used on most periodic samples (entered again after each event), and the bound within
    20x of the ellipsoid's (n = 44: the factored map's path)."""
    kd = _table(name).kalman_design([SYSTEMS[name][1]], SYSTEMS[name][0])
    S, K = len(kd.startup), kd.pattern.K
    n_samples = int(seconds * 50) + 1
    assert n_samples > S + 3 * K      # several periods on the grid
    drop, jitter, restart = S + K + 7, S + 3 * K + 3, S + 2 * K + K // 2
    r = run(name, seconds, noisy=noisy, drop=drop, jitter=jitter, restart=restart)
    assert r["worst"] <= 1.0, r["worst"]
    assert r["entered"] >= 3 and r["left"] >= 2 and r["departures"] >= 1
    assert r["later_on"] >= 2          # reads at a later time and priors with the scalars kept
    assert r["on"] >= 0.5 * (n_samples - S)
    assert 1.0 <= float(np.median(r["ratio"])) <= 20.0


@settings(max_examples=6, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.sampled_from([0.0, 1e-3]), st.booleans())
def test_the_phase_bound_holds_wherever_the_events_fall(drop, restart, tolerance, noisy):
    """``stiff`` (a period of 25 samples after 11 start-up ones): a missing sample and a restart
    anywhere in the second and third periods, with and without a declared clock tolerance (the
    stamps are exact: the tolerance's term only adds), never put a bound below the error."""
    r = run("stiff", 3.0, noisy=noisy, drop=11 + 25 + drop, restart=11 + 50 + restart, later_every=13,
            tolerance=tolerance)
    assert r["worst"] <= 1.0, r["worst"]
    assert r["entered"] >= 2


@settings(max_examples=20, deadline=None)
@given(st.integers(2, 3), st.integers(0, 2**31), st.floats(0.0, 5.0), st.floats(1e-3, 1e3))
def test_the_conversions_hold_exactly(n, seed, spread, beta):
    """The ellipsoid put back from a scalar is ``S >= beta^2 P_j`` and a scalar entered from an
    ellipsoid has ``beta^2 P_j >= S``, both in exact rational arithmetic."""
    rng = np.random.default_rng(seed)
    P = _spd(rng, n, spread)
    pb = PhaseBound.__new__(PhaseBound)
    pb.n = n
    pn = PhaseNorms.__new__(PhaseNorms)
    pn.shapes = [P]
    pn.t = np.array([float(np.linalg.eigvalsh(P)[-1]) * 2.0])
    pn._sqrt_t = np.sqrt(pn.t)
    S, _ = pb._ellipsoid(pn, beta, 0, np.ones(n))
    b2 = Fraction(beta) ** 2
    Se, Pe = _exact(S), _exact(P)
    assert _psd_exact([[Se[i][j] - b2 * Pe[i][j] for j in range(n)] for i in range(n)])
    S2 = _spd(rng, n, spread) * beta
    b = PhaseNorms.start(pn, S2, 0)
    S2e = _exact(S2)
    assert _psd_exact([[Fraction(b) ** 2 * Pe[i][j] - S2e[i][j] for j in range(n)] for i in range(n)])


def test_what_the_option_refuses():
    """Not a Kalman table, no rigorous bound, a declared disturbance, an unknown form: InvalidArgument."""
    system, cycle, _ = SYSTEMS["stiff"]
    table = _table("stiff")
    with pytest.raises(InvalidArgument, match="bound must be one of"):
        so.SwitchedObserver(system, table, "periodic", [cycle], bound="ball")
    with pytest.raises(InvalidArgument, match="needs a Kalman table"):
        so.SwitchedObserver(system, table, "periodic", [cycle], family="kalman-online", bound="phase")
    with pytest.raises(InvalidArgument, match="needs the rigorous bound"):
        so.SwitchedObserver(system, table, "periodic", [cycle], rounding_bound=False, bound="phase")
    dist = Disturbance(np.array([[1.0], [0.0]]), [0.1])
    with pytest.raises(InvalidArgument, match="disturbance"):
        so.SwitchedObserver(system, table, "periodic", [cycle], noise_max=1e-3, disturbance=dist, bound="phase")
    obs = so.SwitchedObserver(system, table, "periodic", [cycle], bound="ellipsoid")
    assert obs.bound_form == "ellipsoid" and obs.rounding.phase is None


@pytest.mark.parametrize("name,noisy", [("osc", True), ("stiff", False)])
def test_stamps_jittered_within_the_tables_tolerance_stay_on_the_phase_path(name, noisy):
    """Every stamp off the grid by up to a quarter of the table's ``dt_tol`` (each sample's step a map of
    its own, the difference from the phase's map in the residual): no bound below the error, and the
    scalars used from the first periodic sample on, entered once."""
    system, cycle, _ = SYSTEMS[name]
    obs = so.SwitchedObserver(system, _table(name), "periodic", [cycle], bound="phase")
    kd = obs.gains.kalman
    r = run(name, (len(kd.startup) + 3 * kd.pattern.K) / 50.0, noisy=noisy, wobble=0.25 * obs.gains.dt_tol,
            later_every=10_000)
    assert r["worst"] <= 1.0, r["worst"]
    assert r["departures"] == 0 and r["entered"] == 1 and r["left"] == 0
    assert r["on"] >= r["samples"] - len(kd.startup) - 1
