"""The prior at a sample's time computed once and shared (:mod:`switchobs_core.runtime.priors`):
what a reader gets from the cache is what a fresh computation gives (the same doubles, in one
process), the Kalman sample's step that takes the prior's product gives the same doubles as one
that forms it, and nothing is served for another time, other columns, or after a sample, a reset,
a set state, a departure, a re-certification or a withdrawal."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
from switchobs_core.bounds.kalman_map import SparseTransition
from switchobs_core.bounds.rigorous import RoundingBound
from switchobs_core.numerics.rounding import ErrorEllipsoid
from switchobs_core.runtime.consistency import InnovationTest, seen_columns
from switchobs_core.runtime.priors import PriorCache

DT = 0.02


@contextlib.contextmanager
def fresh_priors():
    """Every :meth:`PriorCache.at` inside starts from an empty cache: the reads compute afresh."""
    real = PriorCache.at

    def at(self, *a):
        self.clear()
        return real(self, *a)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(PriorCache, "at", at)
        yield


def _same(a, b) -> None:
    """Bit for bit (arrays, floats, None, tuples of them)."""
    if isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b)
        for u, v in zip(a, b):
            _same(u, v)
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray)
        np.testing.assert_array_equal(a, b, strict=True)
    else:
        assert (a is None and b is None) or a == b or (a != a and b != b), (a, b)


def _y(system, ch, x, rng, noise):
    return np.asarray(system.C[ch - 1]) @ x + (noise * rng.uniform(-1, 1, 4) if noise else 0.0)


@pytest.mark.parametrize("noise_max", [None, 1e-3])
def test_shared_prior_equals_fresh_and_the_update_is_unchanged(agents10, noise_max, monkeypatch):
    system, cycle, table, sched, x = agents10
    counts = {"propagated": 0, "sandwich": 0}
    real_prop, real_sw = RoundingBound.propagated, SparseTransition.sandwich_either

    def prop(self, *a, **k):
        counts["propagated"] += 1
        return real_prop(self, *a, **k)

    def sw(self, S, *a):
        counts["sandwich"] += 1
        return real_sw(self, S, *a)
    monkeypatch.setattr(RoundingBound, "propagated", prop)
    monkeypatch.setattr(SparseTransition, "sandwich_either", sw)
    make = (lambda: so.SwitchedObserver(system, table, "periodic", [cycle], e0=10.0, noise_max=noise_max))
    shared, fresh, plain = make(), make(), make()
    rng = np.random.default_rng(11)
    cols = [seen_columns(np.asarray(C)) for C in system.C]
    sets = 1 if noise_max is None else 2
    for k in range(80):
        t = k * DT
        ch = sched.channel_at(t)
        y = _y(system, ch, x, rng, 1e-3 if noise_max else 0.0)
        if k:
            before = dict(counts)
            first = shared.prior(t)
            again = (shared.prior(t), shared.predict(t, hold=True), shared.prior_covariance(t, cols[ch - 1]),
                     shared.prior_covariance(t, cols[ch - 1]))
            assert counts["propagated"] == before["propagated"] + 1     # once for every reader
            with fresh_priors():
                ref = (fresh.prior(t), fresh.predict(t, hold=True), fresh.prior_covariance(t, cols[ch - 1]))
            _same(first, ref[0])
            _same(again[0], ref[0])
            _same(again[1], ref[1])
            _same(again[2], ref[2])
            _same(again[3], ref[2])
            assert again[1] is not first[0]         # each reader its own prediction
            # the innovation test on the pending sets: the doubles of the test on the whole ones
            test = InnovationTest(system.C, None if noise_max is None else (noise_max,) * system.N)
            for c, rows in ((ch, None), (ch % system.N + 1, None), (ch, (0, 1)), (ch, (3,))):
                yc = y if rows is None else y[list(rows)]
                lazy, whole = test.check(shared.prior(t, lazy=True), c, rows, yc), test.check(ref[0], c, rows, yc)
                assert (lazy.innovation, lazy.allowance) == (whole.innovation, whole.allowance)
            if k % 7 == 0:      # the prediction bound at t reads the same step (and forms its own sets)
                with fresh_priors():
                    e_ref = fresh.envelope(t)
                e_got = shared.envelope(t)
                _same((e_got.exact_bound, e_got.noise_bound), (e_ref.exact_bound, e_ref.noise_bound))
            before = dict(counts)
        for obs in (shared, fresh, plain):
            obs.update(t, ch, y)
        if k:       # the steps after a prior took its product: only the plain observer's formed one
            assert counts["sandwich"] - before["sandwich"] == sets
        _same(shared.x_hat, plain.x_hat)
        _same(shared.x_hat, fresh.x_hat)
        ea, eb = shared.envelope(), plain.envelope()
        _same((ea.exact_bound, ea.noise_bound), (eb.exact_bound, eb.noise_bound))
    assert shared.gains_source == "table"


OPS = st.lists(st.sampled_from(["read", "read_later", "update", "wrong_channel", "reset", "set", "recertify",
                                "withdraw", "cols"]), min_size=2, max_size=9)


@settings(max_examples=25, deadline=None)
@given(ops=OPS, noisy=st.booleans(), seed=st.integers(0, 2**16))
def test_nothing_is_served_for_another_time_or_state(agents10, ops, noisy, seed):
    """Random interleavings of reads and changes: every read of one observer equals a fresh
    computation on a twin that saw the same changes (hypothesis)."""
    system, cycle, table, sched, x = agents10
    rng = np.random.default_rng(seed)
    make = (lambda: so.SwitchedObserver(system, table, "periodic", [cycle], e0=10.0,
                                        noise_max=1e-3 if noisy else None))
    obs, twin = make(), make()
    cols = [seen_columns(np.asarray(C)) for C in system.C]
    k = 0

    def both(f):
        f(obs)
        f(twin)

    def read(t, c):
        got = (obs.prior(t), obs.predict(t, hold=True), obs.prior_covariance(t, cols[c]))
        with fresh_priors():
            ref = (twin.prior(t), twin.predict(t, hold=True), twin.prior_covariance(t, cols[c]))
        _same(got, ref)

    both(lambda o: o.update(0.0, sched.channel_at(0.0), _y(system, sched.channel_at(0.0), x, rng, 0.0)))
    for op in ops:
        t_next = (k + 1) * DT
        ch = sched.channel_at(t_next)
        if op == "read":
            read(t_next, ch - 1)
        elif op == "read_later":
            read(t_next + DT / 2, ch - 1)
        elif op == "cols":          # another channel's rows at the same time
            read(t_next, ch % system.N)
        elif op in ("update", "wrong_channel"):
            c = ch if op == "update" else ch % system.N + 1     # a channel off the schedule: a departure
            y = _y(system, c, x, rng, 1e-3 if noisy else 0.0)
            both(lambda o, c=c, y=y, t=t_next: o.update(t, c, y))
            k += 1
        elif op == "reset":
            both(lambda o: o.reset(x * 0.5, obs.t))
        elif op == "set":
            both(lambda o: o.set_estimate(obs.t, {0: float(x[0]) + 0.1}, {0: 1e-4}))
        elif op == "recertify":
            both(lambda o: o.recertify(5.0))
        elif op == "withdraw":
            both(lambda o: setattr(o, "bounds_withdrawn", "withdrawn by the test"))
        read(t_next, ch - 1)        # after every operation: what the next sample would start from


def test_prior_cache_keys():
    c = PriorCache()
    x, y = np.zeros(3), np.zeros(3)
    c.at(1.0, 0.5, x, 1, 1).step = "s"
    assert c.at(1.0, 0.5, x, 1, 1).step == "s"
    for args in ((1.5, 0.5, x, 1, 1), (1.0, 0.6, x, 1, 1), (1.0, 0.5, y, 1, 1), (1.0, 0.5, x, 2, 1),
                 (1.0, 0.5, x, 1, 2)):
        c.at(1.0, 0.5, x, 1, 1).step = "s"
        assert c.at(*args).step is None, args
    cols, other = np.array([0, 4]), np.array([1, 4])
    P = np.arange(4.0).reshape(2, 2)
    assert c.keep_block(cols, P) is P
    B = c.block(cols)
    np.testing.assert_array_equal(B, P)
    B[0, 0] = 9.0       # a reader's copy
    assert c.block(cols)[0, 0] == 0.0
    assert c.block(other) is None and c.block(cols.astype(np.int32)) is None
    c.at(2.0, 0.5, x, 1, 1)
    assert c.block(cols) is None


def test_kept_product_is_taken_once_for_its_map_and_set():
    ell = ErrorEllipsoid(4, 1.0)
    Z = np.ones((4, 4))
    key, other = object(), object()
    ell.keep_product(key, Z)
    assert ell.take_product(other) is None
    assert ell.take_product(key) is None        # dropped by the read above
    ell.keep_product(key, Z)
    assert ell.take_product(key) is Z
    assert ell.take_product(key) is None        # handed over once
    ell.keep_product(key, Z)
    ell.S = ell.S.copy()                        # a step: another set
    assert ell.take_product(key) is None


def test_a_change_of_the_tables_missing_setting_is_served_a_fresh_prior(agents10):
    """The Kalman table's ``missing`` is part of the key: with a grid sample missing, the block read
    after switching ``"table"`` -> ``"online"`` at the same time is the one a fresh read gives."""
    system, cycle, table, sched, x = agents10
    obs = so.SwitchedObserver(system, table, "periodic", [cycle], e0=10.0)
    obs.gains.missing = "table"
    for k in range(3):
        ch = sched.channel_at(k * DT)
        obs.update(k * DT, ch, np.asarray(system.C[ch - 1]) @ x)
    t = 4 * DT                      # the sample at 3 DT missing
    cols = seen_columns(np.asarray(system.C[sched.channel_at(t) - 1]))
    as_table = obs.prior_covariance(t, cols)
    obs.gains.missing = "online"
    read = obs.prior_covariance(t, cols)
    with fresh_priors():
        want = obs.prior_covariance(t, cols)
    _same(read, want)
    assert not np.array_equal(as_table, want)       # the two settings give different blocks here
