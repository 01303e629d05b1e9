"""The factored ellipsoid step of a Kalman sample (:mod:`switchobs_core.bounds.kalman_map`): ``|Z~ - M S M'|
<= c w w'`` entrywise, and ``Z~`` plus the diagonal allowance built from it contains ``M S M'``, for
the exact product (computed in extended precision), on random sparse transitions, gains, rows and
diagonal units; the table and the online family take it from
:data:`~switchobs_core.bounds.kalman_map.SPARSE_MIN_N` states on and their published bounds then
stay within a hair of the dense ones."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
import switchobs_core.bounds.kalman_map as km
from switchobs_core.bounds.kalman_map import KalmanMap, SparseTransition, sparse_transition
from switchobs_core.numerics.propagation import ZOHEntry
from switchobs_core.numerics.rounding import ErrorEllipsoid

LD = np.longdouble
needs_ld = pytest.mark.skipif(np.finfo(LD).eps > 2.0**-60, reason="needs an extended-precision longdouble")


def _block_phi(rng: np.random.Generator, blocks: int, b: int) -> np.ndarray:
    """A block-diagonal transition with ``blocks`` random ``b x b`` blocks near the identity."""
    n = blocks * b
    Phi = np.zeros((n, n))
    for i in range(blocks):
        Phi[i * b:(i + 1) * b, i * b:(i + 1) * b] = np.eye(b) + 0.3 * rng.standard_normal((b, b))
    return Phi


@needs_ld
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 30), b=st.sampled_from([2, 3, 4]),
       p=st.integers(1, 6), sparse_rows=st.booleans(), scale=st.floats(1e-8, 1e8), units=st.booleans())
def test_factored_step_contains_the_exact_product(seed, blocks, b, p, sparse_rows, scale, units):
    rng = np.random.default_rng(seed)
    Phi = _block_phi(rng, blocks, b)
    n = Phi.shape[0]
    if sparse_rows:     # a channel that sees a few states (the column-subset path)
        H = np.zeros((p, n))
        cols = rng.choice(n, size=min(n // 4, 2 * p), replace=False)
        H[:, cols] = rng.standard_normal((p, cols.size))
    else:
        H = rng.standard_normal((p, n))
    K = rng.standard_normal((n, p)) * 0.5
    X = rng.standard_normal((n, n))
    S = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    S = 0.5 * (S + S.T)                 # the ellipsoid keeps S exactly symmetric
    if rng.random() < 0.5:
        S = np.asfortranarray(S)        # the layout the previous step leaves
    d = np.ldexp(1.0, rng.integers(-20, 20, n)) if units else np.ones(n)      # balancing: powers of two
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=d)
    m = KalmanMap(e, K, H, np.eye(n))
    assert m._sp is not None
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S = S.copy(order="K")
    Z, w, c, _ = m.sandwich(ell)
    # exact M S M' in extended precision
    M = (np.eye(n, dtype=LD) - K.astype(LD) @ H.astype(LD)) @ Phi.astype(LD)
    T = M @ S.astype(LD) @ M.T
    bound = LD(c) * np.outer(w.astype(LD), w.astype(LD))
    assert np.all(np.abs(Z.astype(LD) - T) <= bound)
    # the PSD claim of the allowance (rounding.py, step 6): Z~ + c W diag(w d) - M S M' >= 0
    Dm = (Z.astype(LD) + Z.T.astype(LD)) / 2 - T
    Dm[np.diag_indices(n)] += ell._diag(w, c).astype(LD)
    X = Dm.astype(float)
    r = np.sqrt(np.abs(np.diagonal(X))) + 1e-300       # on the diagonal's own scale
    assert float(np.linalg.eigvalsh(X / np.outer(r, r))[0]) >= -1e-6


def test_sparse_form_is_chosen_by_size_and_fill():
    rng = np.random.default_rng(1)
    small = ZOHEntry(_block_phi(rng, 5, 4), None, None, None, 0.02)          # n = 20
    big = ZOHEntry(_block_phi(rng, 12, 4), None, None, None, 0.02)           # n = 48
    dense = ZOHEntry(rng.standard_normal((48, 48)), None, None, None, 0.02)
    assert sparse_transition(small) is None
    assert isinstance(sparse_transition(big), SparseTransition)
    assert sparse_transition(dense) is None
    x = rng.standard_normal(48)
    np.testing.assert_allclose(sparse_transition(big).matvec(x), big.Phi @ x, rtol=1e-13, atol=1e-13)
    S = rng.standard_normal((48, 48))
    np.testing.assert_allclose(sparse_transition(big).sandwich(S), big.Phi @ S @ big.Phi.T, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("family", ["kalman", "kalman-online"])
def test_observer_bounds_match_the_dense_path(agents10, family, monkeypatch):
    """camera_agents(10) (n = 44): estimates equal to the dense path's to rounding, and the exact
    bound within 20 % of the dense path's (both allowances are in the shape of ``|M| s``; the
    factored one has the larger constant; that it still holds is test_audit.py's agents10 and
    blocks14 cases)."""
    system, cycle, table, sched, x = agents10
    rng = np.random.default_rng(5)
    rng.uniform(-3, 3, 22)          # the draws of agents10's positions come first in this stream
    stream = []
    for k in range(150):
        t = k / 50.0
        ch = sched.channel_at(t)
        stream.append((t, ch, np.asarray(system.C[ch - 1]) @ x + 1e-3 * rng.standard_normal(4)))

    def run():
        obs = so.SwitchedObserver(system, table, "periodic", [cycle], family=family)
        out = []
        for t, ch, y in stream:
            obs.update(t, ch, y)
            out.append((obs.x_hat.copy(), obs.envelope(amortised=False).exact_bound))
        return out, obs

    fast, obs = run()
    assert obs.x_hat.shape == (44,)
    monkeypatch.setattr(km, "SPARSE_MIN_N", 10**9)
    dense, _ = run()
    for (xa, ba), (xb, bb) in zip(fast, dense):
        np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-12)
        # the two forms' allowances differ (factored products, the dense |E|): measured within 1.21x
        assert ba <= bb * 1.3 and bb <= ba * 1.3, (ba, bb)
