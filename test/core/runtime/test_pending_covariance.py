"""The LMI family's covariance taken when read (switchobs_core.runtime.covariance.PendingSteps): a run
of equal steps by binary powers equals the steps one by one up to rounding, an observer read at
every sample publishes the same numbers as before (the steps one by one), and one read rarely the
same covariance up to rounding."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
from switchobs_core.model.noise import default_noise
from switchobs_core.numerics.propagation import ZOHCache
from switchobs_core.runtime.covariance import CovarianceStep, PendingSteps
from switchobs_core.runtime.families.base import OPEN_LOOP

CYCLE = so.Cycle.from_ts(2.0, 0.6)


def _stream(system, seconds: float, rate: float = 50.0):
    sched = so.PeriodicSchedule(CYCLE)
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, system.n)
    for k in range(int(seconds * rate)):
        t = k / rate
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        yield t, ch, H @ x + rng.normal(scale=0.01, size=H.shape[0])


def _relative(P: np.ndarray, Q: np.ndarray) -> float:
    return float(np.abs(P - Q).max() / np.abs(Q).max())


@settings(max_examples=30, deadline=None)
@given(m=st.integers(1, 300), seed=st.integers(0, 1000), held=st.booleans(), grow=st.floats(0.8, 1.05))
def test_a_run_by_powers_is_the_steps_one_by_one(m, seed, held, grow):
    """Property: ``m`` equal steps of a random map (contracting or slowly growing, a held noise or
    none) by :class:`PendingSteps` within 1e-12 (relative to the largest entry) of the steps one by one."""
    rng = np.random.default_rng(seed)
    n, p = 5, 2
    A = rng.standard_normal((n, n))
    A = A - (np.max(np.linalg.eigvals(A).real) - np.log(grow) / 0.02) * np.eye(n)     # e^{A dt} grows by ~grow
    C = rng.standard_normal((p, n))
    L = rng.standard_normal((n, p)) * 0.1
    cache = ZOHCache()
    cache.register("g", A, L, None, C=C)
    e = cache.step("g", 0.02)
    cov = CovarianceStep(A, np.zeros((n, 0)), SimpleNamespace(Q_c=0.09 * np.eye(n)), None)
    Rh = 0.01 * np.eye(p) if held else None
    P0 = np.eye(n)
    pend = PendingSteps(cov)
    for _ in range(m):
        assert not pend.push(e, 0.02, Rh)
    assert len(pend) == 1
    got = pend.apply(P0)
    ref = P0
    hn = None if Rh is None else e.GL @ Rh @ e.GL.T
    for _ in range(m):
        ref = cov.step(ref, e, 0.02, hn)
    assert len(pend) == 0
    assert _relative(got, ref) <= 1e-12
    assert np.array_equal(got, got.T)


def test_observer_read_at_every_sample_is_unchanged(paper, paper_table):
    """Read at every sample, the published P is the steps one by one, as the family took them at
    every sample: compared with CovarianceStep driven by hand over the observer's own steps."""
    noise = default_noise(paper)
    obs = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    cov = CovarianceStep(obs.A, obs.B, noise, None)
    P = noise.P0.copy()
    prev_t, prev_key, prev_R = None, None, None
    for t, ch, y in _stream(paper, 6.0):
        if prev_t is not None:
            e = obs.cache.step(prev_key, t - prev_t)
            P = cov.step(P, e, t - prev_t, None if prev_R is None else e.GL @ prev_R @ e.GL.T)
        obs.update(t, ch, y)
        np.testing.assert_array_equal(obs.P, P)
        prev_t, prev_key, prev_R = t, obs.gains.held.key, noise.R(ch)
    assert prev_key != OPEN_LOOP


def test_observer_read_rarely_publishes_the_same_covariance(paper, paper_table):
    """Read every 37th sample and at the end (runs of up to 37 equal steps by powers), P within
    1e-12 of an observer read at every sample, over three cycles; the estimates are the same."""
    noise = default_noise(paper)
    every = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    rare = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    worst = 0.0
    for k, (t, ch, y) in enumerate(_stream(paper, 6.0)):
        np.testing.assert_array_equal(every.update(t, ch, y), rare.update(t, ch, y))
        P = every.P
        if k % 37 == 0:
            worst = max(worst, _relative(rare.P, P))
    worst = max(worst, _relative(rare.P, every.P))
    assert worst <= 1e-12


def test_prior_read_before_each_sample_becomes_the_same_covariance(paper, paper_table, monkeypatch):
    """The prior a consistency test reads before a sample is kept as the step's covariance: P after each
    update is exactly that of an observer that never reads a prior (the same arithmetic), also when
    another prior (another time, another step) was read in between, or the caller wrote into the prior
    it was given; each prior is P through the step, computed by hand. The update then propagates nothing
    where the step is the prior's (a held gain: every sample after the first few)."""
    calls = [0]
    step = CovarianceStep.step

    def counted(self, *a, **k):
        calls[0] += 1
        return step(self, *a, **k)

    monkeypatch.setattr(CovarianceStep, "step", counted)
    noise = default_noise(paper)
    obs = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    ref = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    cov = CovarianceStep(obs.A, obs.B, noise, None)
    prev_t, prev_key, prev_R, kept = None, None, None, 0
    for k, (t, ch, y) in enumerate(_stream(paper, 6.0)):
        if prev_t is not None:
            if k % 5 == 0:          # a prior read at another time first (a sample rejected, say)
                obs.prior_covariance(t - 0.007)
            prior = obs.prior_covariance(t)
            e = obs.cache.step(prev_key, t - prev_t)
            np.testing.assert_array_equal(prior, cov.prior(ref.P, e, t - prev_t,
                                                           None if prev_R is None else e.GL @ prev_R @ e.GL.T))
            if k % 3 == 0:
                prior[:] = 0.0      # the caller's array: the kept prior is a copy
        before = calls[0]
        obs.update(t, ch, y)
        assert obs.P is not None
        kept += prev_t is not None and calls[0] == before
        ref.update(t, ch, y)
        np.testing.assert_array_equal(obs.P, ref.P)
        prev_t, prev_key, prev_R = t, obs.gains.held.key, noise.R(ch)
    assert kept >= 250


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 1000), held=st.booleans())
def test_a_sparse_error_map_is_taken_in_factors(seed, held):
    """Property: at n = 48 with sparse dynamics and a gain on a channel reading four states (E sparse),
    the covariance through 300 steps in factors (CovarianceStep.sparse_map) is within 1e-13 of the
    dense products' (relative to the largest entry), the prior and the step are the same numbers, and a
    dense E (a gain read from every state) or a small system keeps the dense products."""
    rng = np.random.default_rng(seed)
    n, p = 48, 4
    A = np.zeros((n, n))
    for i in range(0, n, 2):                       # double integrators, a little damping
        A[i, i + 1] = 1.0
        A[i + 1, i + 1] = -0.1 * rng.uniform(0.5, 1.5)
    cols = rng.choice(n // 2, size=p, replace=False) * 2
    C = np.zeros((p, n))
    C[np.arange(p), cols] = 1.0
    L = np.zeros((n, p))
    L[cols, np.arange(p)] = rng.uniform(5.0, 20.0, p)
    L[cols + 1, np.arange(p)] = rng.uniform(10.0, 50.0, p)
    cache = ZOHCache()
    cache.register("g", A, L, None, C=C)
    cache.register("dense", A, L, None, C=C + 1e-3 * rng.standard_normal((p, n)))
    e, ed = cache.step("g", 0.02), cache.step("dense", 0.02)
    cov = CovarianceStep(A, np.zeros((n, 0)), SimpleNamespace(Q_c=0.01 * np.eye(n)), None)
    assert cov.sparse_map(e) is not None and cov.sparse_map(ed) is None
    cache.register(OPEN_LOOP, A, None, None)
    assert cov.sparse_map(cache.step(OPEN_LOOP, 0.02)) is None     # nothing held: sparse_transition's case
    hn = None if not held else e.GL @ (1e-4 * np.eye(p)) @ e.GL.T
    Q_d = cov.q_d(0.02)
    P = ref = np.eye(n)
    for _ in range(300):
        prior = cov.prior(P, e, 0.02, hn)
        P = cov.step(P, e, 0.02, hn)
        np.testing.assert_array_equal(prior, P)
        ref = e.E @ ref @ e.E.T + Q_d + (0 if hn is None else hn)
        ref = 0.5 * (ref + ref.T)
    assert _relative(P, ref) <= 1e-13
    small = CovarianceStep(A[:8, :8], np.zeros((8, 0)), SimpleNamespace(Q_c=np.eye(8)), None)
    c8 = ZOHCache()
    c8.register("g", A[:8, :8], L[:8], None, C=C[:, :8])
    assert small.sparse_map(c8.step("g", 0.02)) is None


def test_a_block_of_the_prior_read_with_p_read_at_every_sample(paper, paper_table, monkeypatch):
    """A bias test's block of the prior read before each sample by an observer whose P is read at every
    sample (a publisher): the block is the same doubles as the block of the full prior computed by hand
    from the last P, the family gives it itself (no ``predict_covariance`` of a copy of P), and P after each
    update is exactly that of an observer that reads no prior, with no step propagated again where the
    step is the prior's; writing into the block changes nothing kept."""
    calls = {"step": 0, "predict": 0}
    step = CovarianceStep.step
    predict = type(so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=default_noise(paper)).gains
                   ).predict_covariance

    def counted_step(self, *a, **k):
        calls["step"] += 1
        return step(self, *a, **k)

    def counted_predict(self, *a, **k):
        calls["predict"] += 1
        return predict(self, *a, **k)

    noise = default_noise(paper)
    obs = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    ref = so.SwitchedObserver(paper, paper_table, "periodic", [CYCLE], noise=noise)
    monkeypatch.setattr(CovarianceStep, "step", counted_step)
    monkeypatch.setattr(type(obs.gains), "predict_covariance", counted_predict)
    cov = CovarianceStep(obs.A, obs.B, noise, None)
    cols = np.array([0, 2, paper.n - 1])
    prev_t, prev_key, prev_R, kept = None, None, None, 0
    for t, ch, y in _stream(paper, 6.0):
        if prev_t is not None:
            block = obs.prior_covariance(t, cols)
            e = obs.cache.step(prev_key, t - prev_t)
            full = cov.prior(ref.P, e, t - prev_t, None if prev_R is None else e.GL @ prev_R @ e.GL.T)
            np.testing.assert_array_equal(block, full[np.ix_(cols, cols)])
            block[:] = 0.0
        before = calls["step"]
        obs.update(t, ch, y)
        kept += prev_t is not None and calls["step"] == before
        ref.update(t, ch, y)
        np.testing.assert_array_equal(obs.P, ref.P)         # read at every sample
        prev_t, prev_key, prev_R = t, obs.gains.held.key, noise.R(ch)
    assert calls["predict"] == 0 and kept >= 250
