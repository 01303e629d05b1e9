"""The sample's step takes the held step a prior at its time computed (:mod:`switchobs_core.runtime.priors`):
an observer whose readers took the prior before each sample propagates its estimate once per sample and
publishes the doubles of one that never reads a prior (estimate, covariance, bounds); a prior read for
another time, or before a change of state, is not taken: the step is computed afresh, with the same
doubles as a twin that never read it."""

from __future__ import annotations

import numpy as np
import pytest

import switchobs_core as so
import switchobs_core.runtime.observer as observer_module
from switchobs_core.model.noise import default_noise
from switchobs_core.runtime.consistency import seen_columns

CYCLE = so.Cycle.from_ts(2.0, 0.6)
RATE = 50.0


def _stream(system, seconds: float):
    sched = so.PeriodicSchedule(CYCLE)
    rng = np.random.default_rng(4)
    x = rng.uniform(-1, 1, system.n)
    for k in range(int(seconds * RATE)):
        t = k / RATE
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        yield t, ch, H @ x + rng.uniform(-5e-3, 5e-3, H.shape[0])


def _make(system, table):
    return so.SwitchedObserver(system, table, "periodic", [CYCLE], e0=5.0, noise=default_noise(system),
                               noise_max=(1e-2,) * system.N)


def _same_state(a, b) -> None:
    """Estimate, covariance and both bounds, bit for bit."""
    np.testing.assert_array_equal(a.x_hat, b.x_hat, strict=True)
    np.testing.assert_array_equal(a.P, b.P, strict=True)
    ea, eb = a.envelope(), b.envelope()
    assert (ea.exact_bound, ea.noise_bound) == (eb.exact_bound, eb.noise_bound)
    assert np.isfinite(ea.noise_bound)


@pytest.fixture
def steps(monkeypatch):
    """The number of the estimate's propagations (the observer's ``zoh_step``) so far."""
    calls = [0]
    real = observer_module.zoh_step

    def counted(*a, **k):
        calls[0] += 1
        return real(*a, **k)
    monkeypatch.setattr(observer_module, "zoh_step", counted)
    return calls


def test_a_sample_after_its_prior_propagates_once_and_is_unchanged(paper, paper_table, steps):
    reader, plain = _make(paper, paper_table), _make(paper, paper_table)
    cols = [seen_columns(np.asarray(C)) for C in paper.C]
    shared = 0
    for k, (t, ch, y) in enumerate(_stream(paper, 3.0)):
        if k:
            reader.prior(t)         # what the innovation test and the bias test read
            reader.prior_covariance(t, cols[ch - 1])
            reader.predict(t, hold=True)
            reader.envelope(t)
        before = steps[0]
        reader.update(t, ch, y)
        shared += k > 0 and steps[0] == before      # the prior's step taken: no propagation of its own
        plain.update(t, ch, y)
        _same_state(reader, plain)
    assert shared == k          # every sample after the first


@pytest.mark.parametrize("change", ["later", "recertify", "withdraw", "set", "reset"])
def test_a_prior_for_another_time_or_state_is_not_taken(paper, paper_table, steps, change):
    """A prior read, then the change, then the sample: the sample's step is its own (one propagation),
    and every number equals a twin's that made the same change without reading the prior. (The paper's system
has no input; a held input's change moves the version the cache is keyed by: test_prior_cache.py.)"""
    reader, twin = _make(paper, paper_table), _make(paper, paper_table)
    x0 = np.zeros(paper.n)
    for k, (t, ch, y) in enumerate(_stream(paper, 1.0)):
        if k and k % 4 == 0:
            reader.prior(t + 0.003 if change == "later" else t)
            for o in (reader, twin):
                if change == "recertify":
                    o.recertify(4.0)
                elif change == "withdraw":
                    o.bounds_withdrawn = "withdrawn by the test"
                elif change == "set":
                    o.set_estimate(o.t, {0: 0.01 * k}, {0: 1e-4})
                elif change == "reset":
                    o.reset(x0, o.t)
            before = steps[0]
            reader.update(t, ch, y)
            assert steps[0] == before + 1
        else:
            reader.update(t, ch, y)
        twin.update(t, ch, y)
        np.testing.assert_array_equal(reader.x_hat, twin.x_hat, strict=True)
        np.testing.assert_array_equal(reader.P, twin.P, strict=True)
        ea, eb = reader.envelope(), twin.envelope()
        assert (ea.exact_bound, ea.noise_bound) == (eb.exact_bound, eb.noise_bound)
