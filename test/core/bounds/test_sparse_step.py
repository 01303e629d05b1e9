"""The rigorous sets through a sparse error map in compressed rows
(:func:`switchobs_core.bounds.rigorous.open_loop_product`, :func:`switchobs_core.bounds.kalman_map.sparse_map`):
a block-diagonal ``e^{A dt}`` plus a held innovation's low-rank ``- Gamma L C``, with the allowance
``c = gamma_{2k}`` of sums of at most ``k`` nonzero terms (:mod:`switchobs_core.numerics.rounding`,
step 6). Against the exact product in extended precision: ``|Z~ - E S E'| <= c w w'`` entrywise and
the stepped set contains ``E S E'``; through an LMI observer at 44 states the published bounds are
the dense path's less its larger allowance."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import switchobs_core as so
import switchobs_core.bounds.rigorous as rig
from switchobs_core.bounds.kalman_map import SparseTransition, sparse_map
from switchobs_core.bounds.rigorous import open_loop_product
from switchobs_core.numerics.propagation import ZOHEntry
from switchobs_core.numerics.rounding import ErrorEllipsoid, gamma

LD = np.longdouble
needs_ld = pytest.mark.skipif(np.finfo(LD).eps > 2.0**-60, reason="needs an extended-precision longdouble")


def _held_map(rng: np.random.Generator, blocks: int, b: int, p: int, seen: int) -> tuple[np.ndarray, ...]:
    """``(Phi, GL, C, E)``: a block-diagonal ``Phi`` near the identity, a gain ``GL`` (``n x p``, its
    rows zero outside ``seen`` blocks' states half of the time), rows ``C`` reading ``seen`` states and
    ``E = fl(Phi - fl(GL C))``, the stored map of a held innovation."""
    n = blocks * b
    Phi = np.zeros((n, n))
    for i in range(blocks):
        Phi[i * b:(i + 1) * b, i * b:(i + 1) * b] = np.eye(b) + 0.3 * rng.standard_normal((b, b))
    cols = rng.choice(n, size=seen, replace=False)
    C = np.zeros((p, n))
    C[:, cols] = rng.standard_normal((p, seen))
    GL = 0.2 * rng.standard_normal((n, p))
    if rng.random() < 0.5:
        GL[rng.random(n) < 0.7] = 0.0       # a gain that moves some states only
    return Phi, GL, C, Phi - GL @ C


def _psd_excess(X: np.ndarray) -> float:
    """The least eigenvalue of ``X`` on its diagonal's own scale (>= -1e-6: PSD up to the check's rounding)."""
    r = np.sqrt(np.abs(np.diagonal(X))) + 1e-300
    return float(np.linalg.eigvalsh(X / np.outer(r, r))[0])


@needs_ld
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(12, 30), b=st.sampled_from([2, 3, 4]), p=st.integers(1, 6),
       seen=st.integers(1, 8), scale=st.floats(1e-8, 1e8), units=st.booleans(), fortran=st.booleans(),
       rho=st.sampled_from([0.0, 1e-12, 1e-3]), noise=st.booleans())
def test_sparse_step_contains_the_exact_product(seed, blocks, b, p, seen, scale, units, fortran, rho, noise):
    rng = np.random.default_rng(seed)
    Phi, GL, C, E = _held_map(rng, blocks, b, p, seen)
    n = E.shape[0]
    X = rng.standard_normal((n, n))
    S = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    S = 0.5 * (S + S.T)                 # the ellipsoid keeps S exactly symmetric
    if fortran:
        S = np.asfortranarray(S)        # the layout the previous step leaves
    d = np.ldexp(1.0, rng.integers(-20, 20, n)) if units else np.ones(n)      # balancing: powers of two
    sp = SparseTransition(E)
    k = int(np.count_nonzero(E, axis=1).max())
    assert sp.k == k and sp.c == gamma(2 * k)
    assert sp.c < gamma(2 * n + 2)      # fewer terms than the dense count: the allowance this test checks
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S = S.copy(order="K")
    Z, w, c, mn = open_loop_product(ell, sp)
    T = E.astype(LD) @ S.astype(LD) @ E.T.astype(LD)        # the exact product in extended precision
    assert np.all(np.abs(Z.astype(LD) - T) <= LD(c) * np.outer(w.astype(LD), w.astype(LD)))
    assert np.all(w >= np.abs(E) @ np.sqrt(np.diagonal(S)))
    assert mn >= float(np.abs(E).sum(axis=1).max())
    # the stepped set (the residual's ball, the noise's E(c G G') when drawn) contains E S E'
    if noise:
        Sp, _ = ell.propagate_shaped_product(Z, w, c, rho, mn, GL, 1e-6 * p)
    else:
        Sp, _ = ell.propagate_product(Z, w, c, rho, mn)
    assert _psd_excess((Sp.astype(LD) - T).astype(float)) >= -1e-6


def test_sparse_map_is_chosen_by_size_and_fill():
    """``E`` of a held innovation in compressed rows from ``SPARSE_MIN_N`` states and at most
    ``SPARSE_MAX_FILL`` of nonzeros (kept on the entry), ``Phi``'s own form when ``E`` is ``Phi``."""
    rng = np.random.default_rng(2)
    Phi, GL, C, E = _held_map(rng, 12, 4, 3, 4)            # n = 48
    held = ZOHEntry(Phi, np.eye(48), GL, None, 0.02, E=E, C=C)
    assert isinstance(sparse_map(held), SparseTransition) and sparse_map(held) is held.sparse_E
    assert sparse_map(held).k == int(np.count_nonzero(E, axis=1).max())
    openloop = ZOHEntry(Phi, None, None, None, 0.02)
    assert sparse_map(openloop) is not None and sparse_map(openloop) is openloop.sparse
    dense = rng.standard_normal((48, 48))
    assert sparse_map(ZOHEntry(Phi, np.eye(48), GL, None, 0.02, E=dense, C=C)) is None
    small, GLs, Cs, Es = _held_map(rng, 5, 4, 2, 3)         # n = 20
    assert sparse_map(ZOHEntry(small, np.eye(20), GLs, None, 0.02, E=Es, C=Cs)) is None


@pytest.fixture(scope="module")
def lmi10():
    """camera_agents(10) (n = 44) with an LMI table for residences of 1 s, a seeded state."""
    system = so.camera_agents(10)
    cycle = so.Cycle((1.0,) * 10)
    table = so.design_table(system, cycles=[cycle], delta=0.99, progress=False)
    rng = np.random.default_rng(4)
    x = np.zeros(system.n)
    x[0::4], x[1::4] = rng.uniform(-3, 3, 11), rng.uniform(-3, 3, 11)
    return system, cycle, table, x


def test_lmi_observer_bounds_are_the_dense_paths_less_its_allowance(lmi10, monkeypatch):
    """Every step of both sets takes the sparse map; the estimates are the same doubles, and the exact
    and noise bounds no larger than the dense path's and within 1e-7 of them (measured: at most 4e-9
    smaller, the dense allowance gamma_{2n+2} against gamma_{2k}, k = 6); both hold against the error."""
    system, cycle, table, x0 = lmi10
    sched = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(6)
    from scipy.linalg import expm
    F = expm(np.asarray(system.A) / 50.0)
    stream, x = [], x0.copy()
    for k in range(120):
        t = k / 50.0
        if k:
            x = F @ x
        ch = sched.channel_at(t)
        stream.append((t, ch, np.asarray(system.C[ch - 1]) @ x + 1e-3 * rng.uniform(-1, 1, 4), x))
    calls = []
    real = rig.sparse_map

    def counted(e):         # a step through the sparse form (the kernel's plan or open_loop_product)
        sp = real(e)
        if sp is not None:
            calls.append(sp.k)
        return sp

    def run():
        obs = so.SwitchedObserver(system, table, cycles=[cycle], e0=10.0, noise_max=1e-3)
        out = []
        for t, ch, y, xt in stream:
            xh = obs.update(t, ch, y)
            env = obs.envelope(amortised=False)
            out.append((xh.copy(), env.exact_bound, env.noise_bound, float(np.linalg.norm(xh - xt))))
        return out

    with monkeypatch.context() as m:
        m.setattr(rig, "sparse_map", counted)
        fast = run()
    assert len(calls) >= 2 * (len(stream) - 1) and max(calls) < system.n // 4
    with monkeypatch.context() as m:
        m.setattr(rig, "sparse_map", lambda e: None)
        dense = run()
    for (xa, ea, na, err), (xb, eb, nb, _) in zip(fast, dense):
        np.testing.assert_array_equal(xa, xb)
        assert ea <= eb and eb - ea <= 1e-7 * eb, (ea, eb)
        assert na <= nb and nb - na <= 1e-7 * nb, (na, nb)
        assert err <= na


def test_step_after_the_prior_takes_its_sets(lmi10, monkeypatch):
    """The innovation test's prior at a sample's time, then the sample: the step takes the sets the
    prior computed for the same arguments (half the products), the same doubles as a run without
    the prior."""
    system, cycle, table, x0 = lmi10
    sched = so.PeriodicSchedule(cycle)
    steps = []
    real = rig.RoundingBound._noise

    def counted(self, *a, **k):
        steps.append(1)
        return real(self, *a, **k)
    monkeypatch.setattr(rig.RoundingBound, "_noise", counted)

    def run(with_prior: bool):
        obs = so.SwitchedObserver(system, table, cycles=[cycle], e0=10.0, noise_max=1e-3)
        out, priors = [], []
        for k in range(60):
            t = k / 50.0
            ch = sched.channel_at(t)
            if with_prior and k:
                priors.append(obs.prior(t))
            obs.update(t, ch, np.asarray(system.C[ch - 1]) @ x0)
            b = obs._bound
            out.append((b.ell.S.copy(), b.ellv.S.copy(), b.ell.tr, b.ellv.tr))
        return out, priors

    plain, _ = run(False)
    n_plain, steps[:] = len(steps), []
    with_prior, priors = run(True)
    assert len(steps) == n_plain         # the priors' products, and none again at the samples
    for (S, Sv, tr, trv), (S2, Sv2, tr2, trv2), (_, P, Pv) in zip(plain[1:], with_prior[1:], priors):
        np.testing.assert_array_equal(S, S2)
        np.testing.assert_array_equal(Sv, Sv2)
        assert (tr, trv) == (tr2, trv2)
        np.testing.assert_array_equal(P, S)     # the prior's sets are the sample's step
        np.testing.assert_array_equal(Pv, Sv)


def test_added_set_follows_a_gain_changed_in_place():
    """The added set ``E(c G G')`` is kept per gain array, compared by value: a gain written in place
    gives the set a fresh ellipsoid computes."""
    rng = np.random.default_rng(8)
    n, p = 48, 3
    X = rng.standard_normal((n, n))
    S = X @ X.T / n
    S = 0.5 * (S + S.T)
    G = rng.standard_normal((n, p))
    Z = S.copy()
    w = np.sqrt(np.diagonal(S)).copy()
    kept = ErrorEllipsoid(n, 1.0)
    kept.S = S
    first = kept.propagate_shaped_product(Z.copy(), w, 1e-15, 1e-9, 2.0, G, 1e-4)
    again = kept.propagate_shaped_product(Z.copy(), w, 1e-15, 1e-9, 2.0, G, 1e-4)
    np.testing.assert_array_equal(first[0], again[0])
    G *= 3.0
    fresh = ErrorEllipsoid(n, 1.0)
    fresh.S = S
    np.testing.assert_array_equal(kept.propagate_shaped_product(Z.copy(), w, 1e-15, 1e-9, 2.0, G, 1e-4)[0],
                                  fresh.propagate_shaped_product(Z.copy(), w, 1e-15, 1e-9, 2.0, G, 1e-4)[0])
    assert not np.array_equal(first[0], fresh.propagate_shaped_product(Z.copy(), w, 1e-15, 1e-9, 2.0, G, 1e-4)[0])
