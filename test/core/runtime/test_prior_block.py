"""The online Kalman recursion's prior on a few states, and the re-lock test's cheap refusal.

After a departure from a Kalman table (a missing sample, a step off the grid), the bias test reads
the prior's block on the states its rows see (``SwitchedObserver.prior_covariance(t, cols)``): it
is computed from the recursion's factor on the columns the step's rows touch
(``CovarianceStep.prior_block``), equal to the block of the full propagated prior up to rounding.
The re-lock test is skipped only where its diagonal already fails (``relock_excluded``): it never
decides otherwise than the full test.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import block_diag, expm

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.numerics.kalman_step import symmetrize
from switchobs_core.runtime.covariance import CovarianceStep
from switchobs_core.runtime.families.kalman import relock_excluded
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.table.container import unpack_symmetric
from switchobs_core.table.gains import kalman_table
from switchobs_core.table.kalman import KalmanPhase

RATE = 50.0
CYC = Cycle.from_ts(2.0, 0.6)
EPS = np.finfo(float).eps


def _block_tolerance(E, P, Q, cols):
    """Entrywise: the two orders of summation differ by at most a few ``n eps`` of the sum of the
    absolute products (``|E| |P| |E|' + |Q|``)."""
    n = E.shape[0]
    scale = np.abs(E) @ np.abs(P) @ np.abs(E).T + np.abs(Q)
    return 8 * (n + 2) * EPS * scale[np.ix_(cols, cols)]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), blocks=st.integers(2, 6), wide=st.booleans(), factor=st.booleans())
def test_the_block_is_the_full_priors_block_up_to_rounding(seed, blocks, wide, factor):
    rng = np.random.default_rng(seed)
    A = block_diag(*(rng.normal(size=(3, 3)) for _ in range(blocks)))     # rows touch one block each
    n = A.shape[0]
    noise = SimpleNamespace(Q_c=np.diag(rng.uniform(0.1, 2.0, n)))
    cov = CovarianceStep(A, np.zeros((n, 0)), noise, None)
    dt = 0.02
    Phi = expm(A * dt)
    Phi[np.abs(Phi) < 1e-300] = 0.0
    e = SimpleNamespace(E=Phi, Phi=Phi)              # the open loop: E is Phi
    L = rng.normal(size=(n, 2 * n if wide else n))
    P = symmetrize(L @ L.T)
    cols = np.sort(rng.choice(n, size=int(rng.integers(1, 5)), replace=False))
    full = cov.prior(P, e, dt)[np.ix_(cols, cols)]
    block = cov.prior_block(L if factor else P, e, dt, cols, factor=factor)
    assert block.shape == (cols.size, cols.size)
    np.testing.assert_array_equal(block, block.T)
    Q_d = cov.q_d(dt)
    assert np.all(np.abs(block - full) <= _block_tolerance(Phi, P, Q_d, cols))


@pytest.fixture(scope="module")
def ktable(paper):
    return kalman_table(paper, [design_kalman(paper, CYC, RATE)])


def test_after_a_departure_the_bias_tests_block_comes_from_the_factor(paper, ktable):
    """A missing sample makes the table leave its cache; from there ``prior_covariance(t, cols)`` is
    the recursion's own block (not None, not the stored prior), within rounding of the block of
    the full prior, which is still the propagated one."""
    obs = SwitchedObserver(paper, ktable, "periodic", [CYC], x0=np.zeros(paper.n), e0=1.0)
    obs.gains.missing = "online"       # the missing sample departs
    sched, x = PeriodicSchedule(CYC), np.ones(paper.n)
    cols = np.array([0, 1, 4, 5])
    checked = 0
    for k in [*range(50), *range(51, 80)]:                  # sample 50 missing
        t = k / RATE
        g = obs._gains
        if k > 50 and g.source == "online":
            checked += 1
            block = g.stored_prior(t, t - obs.t, cols)
            assert block is not None
            np.testing.assert_array_equal(obs.prior_covariance(t, cols), block)
            dt = t - obs.t
            e = obs._cache.step(obs._held()[0], dt)
            P = obs.P
            full = obs.prior_covariance(t)
            np.testing.assert_array_equal(full, g.predict_covariance(P, e, dt))
            assert np.all(np.abs(block - full[np.ix_(cols, cols)]) <= _block_tolerance(e.E, P, g._cov.q_d(dt), cols))
            assert g.stored_prior(t, dt) is None             # the full matrix: the observer propagates it
        c = sched.channel_at(t)
        obs.update(t, c, paper.C[c - 1] @ x)
    assert obs.kalman_departures == 1 and checked >= 1


def _full_test_fails_on_the_diagonal(P, S, rtol):
    """The re-lock test of ``KalmanTableGains.sample`` restricted to the diagonal (as it computes it)."""
    d = np.sqrt(np.abs(np.diagonal(S)))
    return not np.all(np.abs(np.diagonal(P) - np.diagonal(S)) <= rtol * np.diagonal(np.outer(d, d)))


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40), wide=st.booleans(),
       rel=st.sampled_from([0.0, 0.5, 0.999, 1.0, 1.001, 1.0 + 1e-9, 1.0 - 1e-9, 2.0, 10.0]),
       rtol=st.sampled_from([1e-3, 1e-2, 1e-8]))
def test_the_relock_test_is_refused_only_where_its_diagonal_fails(seed, n, wide, rel, rtol):
    """``relock_excluded`` True implies the full test's diagonal fails, for stored diagonals at
    and around the tolerance's edge (``S_ii = P_ii (1 +- rel rtol)``); where ``S`` is ``P`` it is
    never True, and far outside the tolerance it is."""
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(n, 2 * n if wide else n)) * rng.uniform(1e-3, 1e3)
    P = symmetrize(L @ L.T)
    sign = rng.choice([-1.0, 1.0], size=n)
    S = P.copy()
    i = int(rng.integers(n))
    S[i, i] = P[i, i] * (1.0 + sign[i] * rel * rtol)
    q = np.einsum("ij,ij->i", L, L)
    m = L.shape[1] + 2
    diag = (q, q * (4.0 * m * EPS / (1.0 - m * EPS)))
    excluded = relock_excluded(diag, np.diagonal(S).copy(), rtol)
    if excluded:
        assert _full_test_fails_on_the_diagonal(P, S, rtol)
    if rel == 0.0:
        assert not excluded
    if rel >= 2.0:
        assert excluded
    assert relock_excluded((np.diagonal(P).copy(), np.zeros(n)), np.diagonal(S).copy(), rtol) == \
        _full_test_fails_on_the_diagonal(P, S, rtol) or rel in (1.0, 1.0 + 1e-9, 1.0 - 1e-9)


def test_non_finite_entries_leave_the_decision_to_the_full_test():
    """NaN gives False (the full test decides); an infinite ``P_ii`` against a finite ``S_ii``
    fails the full test too."""
    assert not relock_excluded((np.array([1.0, np.nan]), np.zeros(2)), np.array([1.0, 1.0]), 1e-3)
    assert not relock_excluded((np.ones(2), np.zeros(2)), np.array([np.nan, 1.0]), 1e-3)
    P, S = np.diag([1.0, np.inf]), np.eye(2)
    assert relock_excluded((np.diagonal(P).copy(), np.zeros(2)), np.ones(2), 1e-3)
    assert _full_test_fails_on_the_diagonal(P, S, 1e-3)


def test_the_packed_diagonal_is_the_matrixs():
    rng = np.random.default_rng(5)
    n = 9
    M = rng.normal(size=(n, n))
    P = M @ M.T
    packed = P[np.triu_indices(n)]
    np.testing.assert_array_equal(unpack_symmetric(packed, n), P)       # the layout P_diagonal reads
    ph = KalmanPhase(1, 0.02, packed.copy(), np.zeros((n, 2)))
    np.testing.assert_array_equal(ph.P_diagonal(), np.diagonal(P))
    assert ph.P_stored.ndim == 1                                          # read from the packed row
    np.testing.assert_array_equal(ph.P_diagonal(), np.diagonal(ph.P_prior))
    assert ph.P_stored.ndim == 2
    np.testing.assert_array_equal(ph.P_diagonal(), np.diagonal(P))
