"""The rigorous sets before a sample (``SwitchedObserver.prior``, the innovation test's) through an
open-loop step whose exponential is sparse (:func:`switchobs_core.bounds.rigorous.open_loop_product`):
``|Z~ - Phi S Phi'| <= c w w'`` entrywise against the exact product (extended precision), the
allowance built from it contains ``Phi S Phi'``, and through the observer the sets equal the dense
path's to rounding and the dense path's larger allowance, for both the exact and the noise set."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
import switchobs_core.bounds.rigorous as rig
from switchobs_core.bounds.kalman_map import sparse_transition
from switchobs_core.bounds.rigorous import open_loop_product
from switchobs_core.numerics.propagation import ZOHEntry
from switchobs_core.numerics.rounding import ErrorEllipsoid
from switchobs_core.runtime.priors import PriorCache

LD = np.longdouble
needs_ld = pytest.mark.skipif(np.finfo(LD).eps > 2.0**-60, reason="needs an extended-precision longdouble")


@needs_ld
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 30), b=st.sampled_from([2, 3, 4]),
       scale=st.floats(1e-8, 1e8), units=st.booleans(), fortran=st.booleans())
def test_open_loop_product_contains_the_exact_product(seed, blocks, b, scale, units, fortran):
    rng = np.random.default_rng(seed)
    n = blocks * b
    Phi = np.zeros((n, n))
    for i in range(blocks):
        Phi[i * b:(i + 1) * b, i * b:(i + 1) * b] = np.eye(b) + 0.3 * rng.standard_normal((b, b))
    X = rng.standard_normal((n, n))
    S = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    S = 0.5 * (S + S.T)
    if fortran:
        S = np.asfortranarray(S)
    d = np.ldexp(1.0, rng.integers(-20, 20, n)) if units else np.ones(n)
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=d)
    sp = sparse_transition(e)
    assert sp is not None
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S = S.copy(order="K")
    Z, w, c, mn = open_loop_product(ell, sp)
    T = Phi.astype(LD) @ S.astype(LD) @ Phi.T.astype(LD)
    assert np.all(np.abs(Z.astype(LD) - T) <= LD(c) * np.outer(w.astype(LD), w.astype(LD)))
    assert mn >= float(np.abs(Phi).sum(axis=1).max())
    # the PSD claim of the allowance (rounding.py, step 6): sym(Z~) + c W diag(w d) - Phi S Phi' >= 0
    Dm = (Z.astype(LD) + Z.T.astype(LD)) / 2 - T
    Dm[np.diag_indices(n)] += ell._diag(w, c).astype(LD)
    Xd = Dm.astype(float)
    r = np.sqrt(np.abs(np.diagonal(Xd))) + 1e-300
    assert float(np.linalg.eigvalsh(Xd / np.outer(r, r))[0]) >= -1e-6
    # and the propagated set (rho = 0) contains it as well
    Sp, _ = ell.propagate_product(Z.copy(), w, c, 0.0, mn)
    Dp = Sp.astype(LD) - T
    Xp = Dp.astype(float)
    rp = np.sqrt(np.abs(np.diagonal(Xp))) + 1e-300
    assert float(np.linalg.eigvalsh(Xp / np.outer(rp, rp))[0]) >= -1e-6


def _prior_pairs(agents10, noise_max, monkeypatch) -> tuple[list, int]:
    """Before each sample of a 44-state Kalman table run (``agents10``): the prior sets the
    observer gives and those of the dense product on the same state; and the calls of the sparse form."""
    calls = []
    real = rig.sparse_map

    def counted(e):         # a set through the sparse form (the kernel's plan or open_loop_product)
        sp = real(e)
        calls.append(sp is not None)
        return sp
    monkeypatch.setattr(rig, "sparse_map", counted)
    real_at = PriorCache.at

    def fresh_at(self, *a):
        self.clear()
        return real_at(self, *a)
    system, cycle, table, sched, x = agents10
    rng = np.random.default_rng(3)
    obs = so.SwitchedObserver(system, table, "periodic", [cycle], e0=10.0, noise_max=noise_max)
    out = []
    for k in range(60):
        t = k / 50.0
        ch = sched.channel_at(t)
        y = np.asarray(system.C[ch - 1]) @ x + (0.0 if noise_max is None else 1e-3 * rng.uniform(-1, 1, 4))
        if k:
            fast = obs.prior(t)
            with monkeypatch.context() as m:
                m.setattr(rig, "sparse_map", lambda e: None)
                m.setattr(PriorCache, "at", fresh_at)       # computed again, not the prior kept for t
                dense = obs.prior(t)
            out.append((fast, dense))
        obs.update(t, ch, y)
    return out, sum(calls)


@pytest.mark.parametrize("noise_max", [None, 1e-3])
def test_observer_prior_matches_the_dense_path(agents10, noise_max, monkeypatch):
    pairs, calls = _prior_pairs(agents10, noise_max, monkeypatch)
    assert calls == len(pairs) * (1 if noise_max is None else 2)      # every prior took the sparse form
    for (xa, Sa, Sva), (xb, Sb, Svb) in pairs:
        np.testing.assert_array_equal(xa, xb)
        for A, B in ((Sa, Sb), (Sva, Svb)):
            if B is None:
                assert A is None
                continue
            # other roundings of one product and a smaller allowance (gamma_2k, k = 2 here, for the
            # dense product's gamma_2n+2): equal to a hair of the largest entry (measured at most 2.6e-12
            # of it, the dense allowance's size), and the diagonal no larger than the dense one's
            big = float(np.abs(B).max())
            np.testing.assert_allclose(A, B, rtol=0, atol=1e-11 * big)
            assert np.all(np.diagonal(A) <= np.diagonal(B) + 1e-14 * big)
