"""The LMI family's prior block for the bias test (switchobs_core.runtime.covariance.HeldBlock).

A held gain's error map ``E = e^{A dt} - Gamma_A L C`` changes only the rows and columns of the
states its channel reads: the smallest set ``K`` holding a sample's columns that ``E`` maps into
itself is a few states (one agent and the common ones). The block ``P[K, K]`` carried through such
steps gives the prior's block on the sample's columns without the n x n prior; it equals the block
of the full products up to rounding (sums of the same nonzero products in another order), within
the bound stated in :func:`_step_rounding` carried through the steps.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import block_diag, expm

import switchobs_core as so
from switchobs_core.design.lmi import design_table
from switchobs_core.model.noise import default_noise
from switchobs_core.model.scenarios import load_system
from switchobs_core.numerics.kalman_step import symmetrize
from switchobs_core.runtime.consistency import seen_columns
from switchobs_core.runtime.covariance import CovarianceStep, HeldBlock

EPS = np.finfo(float).eps
DT = 0.02


def _step_rounding(E, P, Q, H):
    """Entrywise bound on the difference of two summation orders of ``E P E' + Q + H``: a few
    ``n eps`` of the sum of the absolute terms (``|E| |P| |E|' + |Q| + |H|``)."""
    n = E.shape[0]
    return 8 * (n + 2) * EPS * (np.abs(E) @ np.abs(P) @ np.abs(E).T + np.abs(Q) + np.abs(H))


def _agents(rng, agents, size, common):
    """A block-diagonal ``A`` (the common states first, then one block per agent) and, per agent, a
    held gain's step reading the common states and that agent's (``E = Phi - G C``, ``G`` nonzero
    on those rows only): the structure of ``camera_agents``."""
    A = block_diag(*(rng.normal(size=(s, s)) for s in [common] + [size] * agents))
    n = A.shape[0]
    Phi = expm(A * DT)
    Phi[np.abs(Phi) < 1e-300] = 0.0
    steps = []
    for i in range(agents):
        seen = np.r_[np.arange(common), common + i * size + np.arange(size)]
        C = np.zeros((2, n))
        C[:, seen] = rng.normal(size=(2, seen.size))
        GL = np.zeros((n, 2))
        GL[seen] = rng.normal(size=(seen.size, 2)) * 0.02
        steps.append((SimpleNamespace(E=Phi - GL @ C, Phi=Phi, GL=GL), seen))
    return A, steps


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), agents=st.integers(2, 14), size=st.integers(2, 4),
       held=st.booleans(), run=st.integers(1, 12))
def test_the_carried_block_is_the_full_steps_block_up_to_rounding(seed, agents, size, held, run):
    """Property: random agent-structured maps, PSD ``P``, a sample's columns: the closure holds the
    columns and ``E`` maps it into itself; the prior's block after ``run`` steps on one channel,
    carried on ``K``, is the block of the full steps within the summed rounding bound (and None
    where ``K`` exceeds a quarter of the states)."""
    rng = np.random.default_rng(seed)
    common = 2
    A, steps = _agents(rng, agents, size, common)
    n = A.shape[0]
    cov = CovarianceStep(A, np.zeros((n, 0)), SimpleNamespace(Q_c=np.diag(rng.uniform(0.1, 2.0, n))), None)
    Q = cov.q_d(DT)
    e, seen = steps[int(rng.integers(agents))]
    cols = np.sort(rng.choice(seen, size=int(rng.integers(1, seen.size + 1)), replace=False))
    R = np.diag(rng.uniform(0.01, 1.0, 2)) if held else None
    H = np.zeros((n, n)) if R is None else e.GL @ R @ e.GL.T
    blk = HeldBlock(cov)
    got = blk.closure(e, cols)
    K_expected = np.union1d(np.arange(common), seen)        # one agent and the common states
    if K_expected.size > HeldBlock.MAX_SHARE * n:
        assert got is None
        return
    K, ix = got
    np.testing.assert_array_equal(K, K_expected)
    assert not np.any(np.delete(e.E[K], K, axis=1))
    M = rng.normal(size=(n, n))
    P = symmetrize(M @ M.T)
    blk.start(P, K)
    bound = np.zeros((K.size, K.size))
    for _ in range(run):
        prior = blk.prior(e, DT, R)
        full = cov.prior(P, e, DT, None if R is None else H)
        bound = (np.abs(e.E[np.ix_(K, K)]) @ bound @ np.abs(e.E[np.ix_(K, K)]).T
                 + _step_rounding(e.E, P, Q, H)[np.ix_(K, K)])
        assert np.all(np.abs(prior - full[np.ix_(K, K)]) <= bound)
        np.testing.assert_array_equal(prior, prior.T)
        assert prior[ix].shape == (cols.size, cols.size)
        blk.step(e, DT, R)                  # the prior becomes the block kept
        np.testing.assert_array_equal(blk.B, prior)
        P = full


def test_a_step_that_leaves_the_block_drops_it():
    """Another channel's step reads states outside ``K``: the block is dropped (the owner starts
    it again from the full covariance)."""
    rng = np.random.default_rng(3)
    A, steps = _agents(rng, 12, 3, 2)
    n = A.shape[0]
    cov = CovarianceStep(A, np.zeros((n, 0)), SimpleNamespace(Q_c=np.eye(n)), None)
    (e1, seen1), (e2, _) = steps[0], steps[1]
    blk = HeldBlock(cov)
    K, _ = blk.closure(e1, seen1)
    blk.start(np.eye(n), K)
    blk.step(e1, DT, None)
    assert blk.holds(K)
    blk.step(e2, DT, None)          # the common rows of e2 read agent 2
    assert blk.K is None and not blk.holds(K)


@pytest.fixture(scope="module")
def agents8(tmp_path_factory):
    path = Path(tmp_path_factory.mktemp("agents8")) / "system.yaml"
    path.write_text("scenario: camera_agents\nagents: 8\nD_agents: " + str([[0.0, 0.05]] * 8) + "\n")
    system = load_system(str(path))
    return system, design_table(system, [so.Cycle([1.0] * 8)], progress=False)


def test_the_observers_prior_block_is_the_full_priors_and_keeps_the_covariance(agents8):
    """An LMI observer at 8 agents (n = 36) read as the bias test reads it (the prior's block on
    each sample's columns) beside one whose full prior is read at every sample: the blocks agree
    within 1e-11 of the block's largest entry (runs of 50 steps carried on 8 states against the
    steps one by one; measured 1.4e-12, the first seconds' blocks a cancellation of terms a
    thousand times larger, from ``P0``), the full prior is never formed for a block, and the
    covariance kept (its steps taken when read, a run by powers) is the other's within 1e-12
    relative (measured 3.3e-14). One whose ``P`` is read at every sample takes the full prior instead
    (the step the sample then takes): its blocks are the full prior's, the same doubles."""
    system, table = agents8
    cyc = so.Cycle([1.0] * 8)
    obs = so.SwitchedObserver(system, table, "periodic", [cyc], noise=default_noise(system))
    other = so.SwitchedObserver(system, table, "periodic", [cyc], noise=default_noise(system))
    reader = so.SwitchedObserver(system, table, "periodic", [cyc], noise=default_noise(system))
    sched = so.PeriodicSchedule(cyc)
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, system.n)
    F = expm(np.asarray(system.A) * DT)
    full_calls = 0
    predict = obs.gains.predict_covariance

    def counted(*a, **k):
        nonlocal full_calls
        full_calls += 1
        return predict(*a, **k)

    obs.gains.predict_covariance = counted
    worst = 0.0
    for k in range(600):                                    # 12 s: every channel, and again
        t = k * DT
        ch = sched.channel_at(t)
        y = np.asarray(system.C[ch - 1]) @ x + rng.normal(scale=1e-3, size=4)
        x = F @ x
        if k:
            cols = seen_columns(np.asarray(system.C[ch - 1]))
            block = obs.prior_covariance(t, cols)
            full = other.prior_covariance(t)[np.ix_(cols, cols)]
            np.testing.assert_array_equal(reader.prior_covariance(t, cols), full)    # P read: the full prior
            assert block.shape == (cols.size, cols.size)
            worst = max(worst, float(np.abs(block - full).max() / np.abs(full).max()))
        obs.update(t, ch, y)
        other.update(t, ch, y)
        reader.update(t, ch, y)
        assert reader.P is not None      # read at every sample, as a published estimate reads it
    assert full_calls == 0
    assert worst <= 1e-11
    P, Po = obs.P, other.P
    assert float(np.abs(P - Po).max() / np.abs(Po).max()) <= 1e-12



def test_a_read_covariance_in_fortran_order_gives_the_full_priors_doubles(agents8):
    """Where ``P`` is read, the prior's block is taken from the full prior, kept for the step: that
    prior is the one a reader's copy of ``P`` gives (the same doubles), also when the covariance kept
    is in Fortran order (the products' rounding depends on the layout: C order is used), so the
    covariance after the step is the same whichever path the prior took."""
    system, table = agents8
    cyc = so.Cycle([1.0] * 8)
    reader = so.SwitchedObserver(system, table, "periodic", [cyc], noise=default_noise(system))
    other = so.SwitchedObserver(system, table, "periodic", [cyc], noise=default_noise(system))
    sched = so.PeriodicSchedule(cyc)
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, system.n)
    X = rng.standard_normal((system.n, system.n))
    P = X @ X.T + system.n * np.eye(system.n)
    for k in range(8):
        t = k * DT
        ch = sched.channel_at(t)
        if k:
            cols = seen_columns(np.asarray(system.C[ch - 1]))
            full = other.prior_covariance(t)[np.ix_(cols, cols)]        # from the copy other.P gave
            np.testing.assert_array_equal(reader.prior_covariance(t, cols), full)
        y = np.asarray(system.C[ch - 1]) @ x
        reader.update(t, ch, y)
        other.update(t, ch, y)
        np.testing.assert_array_equal(reader.P, other.P)               # read at every sample
        if k % 2 == 0:
            reader.gains.set_covariance(np.asfortranarray(P))
            other.gains.set_covariance(np.ascontiguousarray(P))
            assert reader.P is not None and other.P is not None
