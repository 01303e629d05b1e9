"""The compiled kernel's step of the exact set through a Kalman sample's factored map
(:func:`~switchobs_core.numerics.dense_kernel.sandwich`, :func:`~switchobs_core.numerics.dense_kernel.factored`,
:func:`~switchobs_core.numerics.dense_kernel.open_plan`) against the numpy path it stands for.

``Phi~ S Phi~'`` is the same doubles as scipy's products (bit for bit, signs of zeros included). The
factored step and the prior's plan sum in index order where numpy and BLAS sum in their own orders: the
allowances they carry (:mod:`switchobs_core.bounds.kalman_map`, steps 1-3; :mod:`switchobs_core.numerics.rounding`,
steps 5-8) are stated for the standard model, ``gamma_m`` for a sum of ``m`` terms in any order, and each scalar
sum of nonnegative terms is rounded up by ``1 + 2 gamma_{n+2}`` whatever its order; so the two sets differ in
their last bits only (here: every entry within 1e-12 of ``sqrt(S'_ii S'_kk)``, the trace and the diagonal within
1e-12 relative), and the kernel's set contains ``M S M'`` computed in extended precision as numpy's does. The
observer's bounds against an extended-precision plant with the kernel are the audits of ``test_audit.py``
(``agents10``, ``blocks14``: the factored path), which run it wherever it is built."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import block_diag, expm

import switchobs_core as so
from switchobs_core.bounds.kalman_map import KalmanMap, SparseTransition
from switchobs_core.numerics import dense_kernel
from switchobs_core.numerics.propagation import ZOHEntry
from switchobs_core.numerics.rounding import ErrorEllipsoid

LD = np.longdouble
needs_kernel = pytest.mark.skipif(dense_kernel.FACTORED is None, reason="the compiled kernel is not built")
needs_ld = pytest.mark.skipif(np.finfo(LD).eps > 2.0**-60, reason="needs an extended-precision longdouble")
TOL = 1e-12


def _case(seed: int, blocks: int, b: int, p: int, spread: bool, units: bool):
    """A block-diagonal ``Phi~``, rows ``H`` (one state a row, or a few columns with random weights), a gain,
    a PSD ``S`` (exactly symmetric, C- or F-ordered) and a balancing."""
    rng = np.random.default_rng(seed)
    Phi = block_diag(*(np.eye(b) + 0.3 * rng.standard_normal((b, b)) for _ in range(blocks)))
    n = Phi.shape[0]
    H = np.zeros((p, n))
    if spread:
        cols = rng.choice(n, size=min(n // 4, 2 * p), replace=False)
        H[:, cols] = rng.standard_normal((p, cols.size))
    else:
        H[np.arange(p), rng.choice(n, size=p, replace=False)] = 1.0
    K = rng.standard_normal((n, p)) * 0.5
    X = rng.standard_normal((n, n))
    S = X @ X.T / n + 1e-3 * np.eye(n)
    S = 0.5 * (S + S.T)
    if rng.random() < 0.5:
        S = np.asfortranarray(S)
    d = np.ldexp(1.0, rng.integers(-20, 20, n)) if units else np.ones(n)
    return Phi, H, K, S, d


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.int64)


@needs_kernel
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(10, 40), b=st.sampled_from([1, 2, 3, 4]),
       zeros=st.booleans())
def test_sandwich_gives_scipys_doubles(seed, blocks, b, zeros):
    rng = np.random.default_rng(seed)
    Phi = _case(seed, blocks, b, 1, False, False)[0]
    n = Phi.shape[0]
    S = rng.standard_normal((n, n))
    if zeros:       # signed zeros and exact zeros: 0.0 + (-0.0) is +0.0 in scipy's sums, so it must be here
        S[rng.random((n, n)) < 0.3] = -0.0
        S[rng.random((n, n)) < 0.3] = 0.0
    sp = SparseTransition(Phi)
    for T in (S, np.asfortranarray(S)):
        got = sp.sandwich_either(T, np.empty((n, n)))
        with dense_kernel.numpy_factored():
            ref = sp.sandwich_either(T, np.empty((n, n)))
            ref2 = sp.sandwich_either(T)
        assert got.flags.c_contiguous
        np.testing.assert_array_equal(_bits(got), _bits(ref))
        np.testing.assert_array_equal(_bits(got), _bits(ref2))


def _steps(Phi, H, K, S, d, rho):
    """The set after one factored step by the kernel and by numpy, from the same ``S``."""
    n = Phi.shape[0]
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=d)
    out = []
    for kernel in (True, False):
        m = KalmanMap(e, K, H, np.eye(n))
        ell = ErrorEllipsoid(n, 1.0, d)
        ell.S = S.copy(order="K")
        if kernel:
            assert m.step(ell, rho)
        else:
            with dense_kernel.numpy_factored():
                assert not m.step(ell, rho)
                Z, w, c, mn = m.sandwich(ell)
                ell.S, ell.tr = ell.propagate_product(Z, w, c, rho, mn)
        out.append((ell.S, ell.tr, ell.lam_scaled(), m))
    return out


@needs_kernel
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 40), b=st.sampled_from([2, 3, 4]),
       p=st.integers(1, 6), spread=st.booleans(), units=st.booleans(),
       rho=st.sampled_from([0.0, 1e-12, 1e-6, 1.0]))
def test_factored_step_is_numpys_set_to_its_last_bits(seed, blocks, b, p, spread, units, rho):
    case = _case(seed, blocks, b, p, spread, units)
    (A, tra, lsa, _), (B, trb, lsb, _) = _steps(*case, rho)
    np.testing.assert_array_equal(A, A.T)           # exactly symmetric
    scale = np.sqrt(np.outer(np.diagonal(B), np.diagonal(B)))
    assert np.all(np.abs(A - B) <= TOL * scale)
    np.testing.assert_allclose(np.diagonal(A), np.diagonal(B), rtol=TOL, atol=0)
    assert abs(tra - trb) <= TOL * trb and abs(lsa - lsb) <= TOL * lsb
    # tr: the new diagonal's sum rounded up, ls its balanced trace rounded up (against extended sums)
    dA = np.diagonal(A).astype(LD)
    assert tra >= float(dA.sum()) and lsa >= float((dA / case[4].astype(LD) ** 2).sum())


@needs_kernel
@needs_ld
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 40), b=st.sampled_from([2, 3, 4]),
       p=st.integers(1, 6), spread=st.booleans(), units=st.booleans())
def test_kernels_set_contains_the_exact_image(seed, blocks, b, p, spread, units):
    """``rho = 0`` (``alpha = 1``): the kernel's ``S'`` minus ``M S M'`` (extended precision) is PSD, as
    numpy's is (test_kalman_map.py): the allowance covers the kernel's rounding."""
    Phi, H, K, S, d = _case(seed, blocks, b, p, spread, units)
    (A, _, _, _), _ = _steps(Phi, H, K, S, d, 0.0)
    n = Phi.shape[0]
    M = (np.eye(n, dtype=LD) - K.astype(LD) @ H.astype(LD)) @ Phi.astype(LD)
    Dm = (A.astype(LD) - M @ S.astype(LD) @ M.T).astype(float)
    r = np.sqrt(np.abs(np.diagonal(Dm))) + 1e-300
    assert float(np.linalg.eigvalsh(Dm / np.outer(r, r))[0]) >= -1e-6


@needs_kernel
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 40), b=st.sampled_from([2, 3, 4]),
       units=st.booleans(), rho=st.sampled_from([0.0, 1e-12, 1e-6, 1.0, 1e300, float("nan")]))
def test_open_plan_is_numpys_plan_to_its_last_bits(seed, blocks, b, units, rho):
    Phi, _, _, S, d = _case(seed, blocks, b, 1, False, units)
    n = Phi.shape[0]
    sp = SparseTransition(Phi)
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S = S
    Z = sp.sandwich_either(S, ell.scratch())
    got = ell.pending_open(Z, sp.abs_rows, sp.c, rho, sp.inf_norm)
    ref = ell.pending(Z, ell.image_bound(sp.abs_matvec), sp.c, rho, sp.inf_norm)
    (a1, t1, _, q1, s1, r1), (a2, t2, _, q2, s2, r2) = got._plan, ref._plan
    assert a1 == a2 or abs(a1 - a2) <= TOL * a2         # alpha: chosen from sums in another order
    assert t1 == t2 or abs(t1 - t2) <= TOL * t2
    np.testing.assert_allclose(q1, q2, rtol=TOL, atol=0)
    np.testing.assert_allclose((s1, r1), (s2, r2), rtol=TOL, atol=0)
    A, B = got.full(), ref.full()
    fin = np.isfinite(B)
    np.testing.assert_array_equal(np.isfinite(A), fin)
    np.testing.assert_allclose(A[fin], B[fin], rtol=TOL, atol=TOL * float(np.abs(B[fin]).max(initial=0.0)))


@needs_kernel
def test_a_refused_call_leaves_the_product_to_numpy(monkeypatch):
    """The kernel refuses (here: every call) -> :meth:`KalmanMap.step` changes nothing and keeps the product
    it took for :meth:`KalmanMap.sandwich`: the numpy path's doubles, bit for bit."""
    Phi, H, K, S, d = _case(7, 20, 2, 4, False, True)
    n = Phi.shape[0]
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=d)

    def refuse(*a):
        raise ValueError("refused")
    out = []
    for refused in (True, False):
        m = KalmanMap(e, K, H, np.eye(n))
        ell = ErrorEllipsoid(n, 1.0, d)
        ell.S = S.copy()
        with monkeypatch.context() as mp:
            if refused:
                mp.setattr(dense_kernel, "FACTORED", refuse)
                before = dense_kernel.FALLBACKS["factored"]
                assert not m.step(ell, 1e-6) and dense_kernel.FALLBACKS["factored"] == before + 1
                assert ell.S is not None and np.array_equal(ell.S, S)
                assert ell._kept is not None                # the product, kept for sandwich()
            else:
                mp.setattr(dense_kernel, "FACTORED", None)
            Z, w, c, mn = m.sandwich(ell)
            out.append(ell.propagate_product(Z, w, c, 1e-6, mn))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert out[0][1] == out[1][1]


@needs_kernel
def test_observer_with_the_kernel_is_numpys_to_the_last_bits(agents10):
    """A 44-state Kalman table run (every sample a factored step, every prior a kernel's plan): the estimates
    the same doubles, the exact bound within 1e-12 relative of numpy's, and the kernel took every step."""
    system, cycle, table, sched, x0 = agents10
    F = expm(np.asarray(system.A) / 50.0)
    xs = [x0]
    while len(xs) < 150:
        xs.append(F @ xs[-1])
    calls = {"step": 0}
    real = KalmanMap.step

    def counted(self, ell, rho):
        done = real(self, ell, rho)
        calls["step"] += bool(done)
        return done

    def run():
        obs = so.SwitchedObserver(system, table, "periodic", [cycle], e0=10.0)
        out = []
        for k, x in enumerate(xs):
            t = k / 50.0
            if k % 3 == 1:
                obs.prior(t)        # the prior's product, taken by the sample's step
            xh = obs.update(t, sched.channel_at(t), np.asarray(system.C[sched.channel_at(t) - 1]) @ x)
            env = obs.envelope(amortised=False)
            out.append((xh.copy(), env.exact_bound, float(np.linalg.norm(xh - x))))
        return out

    KalmanMap.step = counted
    try:
        fast = run()
        n_kernel = calls["step"]
        with dense_kernel.numpy_factored():
            ref = run()
    finally:
        KalmanMap.step = real
    assert n_kernel >= 140 and calls["step"] == n_kernel       # the kernel's steps; none in numpy's run
    for (xa, ba, err), (xb, bb, _) in zip(fast, ref):
        np.testing.assert_array_equal(xa, xb)
        assert abs(ba - bb) <= TOL * bb
        assert err <= ba


@needs_kernel
def test_the_kernel_refuses_what_it_cannot_read():
    """Indices of another type, compressed rows out of range, an output sharing an input's memory: ValueError
    from the module, None from the wrappers (counted), and nothing written."""
    Phi, H, K, S, d = _case(3, 20, 2, 4, False, False)
    n = Phi.shape[0]
    sp = SparseTransition(Phi)
    ip, ix, adv = sp.abs_rows
    ell = ErrorEllipsoid(n, 1.0, d)
    hp, hj, hv = np.array([0, 1, 2, 3, 4], dtype=np.intp), np.arange(4, dtype=np.intp), np.ones(4)
    args = (ip, ix, adv, K, hp, hj, hv, ell._faux, 1e-6, 1.0, 1e-15, 1e-15, 1e-300, 1.0)
    Y = S.copy()
    for bad in ({0: ip.astype(np.int32)}, {1: np.where(ix == ix.max(), n, ix)}, {4: np.array([0, 1, 2, 3, 5])}):
        a = list(args)
        for i, v in bad.items():
            a[i] = v
        before = dense_kernel.FALLBACKS["factored"]
        assert dense_kernel.factored(Y, S, *a) is None
        assert dense_kernel.FALLBACKS["factored"] == before + 1
        np.testing.assert_array_equal(Y, S)
    with pytest.raises(ValueError):         # a gain of float32
        dense_kernel.FACTORED(S.copy(), S.copy(), *args[:3], K.astype(np.float32), *args[4:])
    with pytest.raises(ValueError):         # Y is the gain's memory: an output sharing an input's
        Kbig = np.zeros((n, n))
        dense_kernel.FACTORED(Kbig, S, ip, ix, adv, Kbig.reshape(-1)[: n * 4].reshape(n, 4), *args[4:])
    X = np.empty((n, n))
    assert dense_kernel.sandwich(ip.astype(np.int32), ix, sp._dv, S, X) is None
    assert dense_kernel.sandwich(ip, ix, sp._dv, S, S) is None          # the scratch is the input


@needs_kernel
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), m=st.integers(1, 8), fortran=st.booleans(), alpha=st.floats(1.0, 1e3))
def test_a_pending_sets_block_is_numpys_bit_for_bit(seed, m, fortran, alpha):
    """:meth:`PendingSet.block` of a prior (no shaped set) by the kernel: numpy's operations in its order, the
    same doubles as numpy's block and as the assembled set's."""
    rng = np.random.default_rng(seed)
    n = 44
    Z = rng.standard_normal((n, n))
    Z[rng.random((n, n)) < 0.2] = -0.0
    if fortran:
        Z = np.asfortranarray(Z)
    q = np.abs(rng.standard_normal(n))
    cols = np.sort(rng.choice(n, size=m, replace=False)).astype(np.intp)
    ell = ErrorEllipsoid(n, 1.0)
    plan = (alpha, 1.0, None, q, 0.0, 0.0)
    got = ell._block(Z, plan, cols)
    with dense_kernel.numpy_factored():
        ref = ell._block(Z, plan, cols)
    full = ell._apply(Z.copy(order="K"), plan)[0][np.ix_(cols, cols)]
    np.testing.assert_array_equal(_bits(got), _bits(ref))
    np.testing.assert_array_equal(_bits(got), _bits(full))


@needs_kernel
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), blocks=st.integers(20, 40), p=st.integers(1, 6), spread=st.booleans(),
       units=st.booleans())
def test_kappa_is_numpys_to_its_last_bits(seed, blocks, p, spread, units):
    """:attr:`KalmanMap.kappa` on the factored path by the kernel: within 1e-13 relative of numpy's sums (both
    rounded up by the same factor, which covers any order) and never below the exact ``1 + sqrt(one inf)``."""
    Phi, H, K, _, d = _case(seed, blocks, 2, p, spread, units)
    n = Phi.shape[0]
    e = ZOHEntry(Phi, None, None, None, 0.02, scale=d)
    got = KalmanMap(e, K, H, np.eye(n)).kappa
    with dense_kernel.numpy_factored():
        ref = KalmanMap(e, K, H, np.eye(n)).kappa
    assert abs(got - ref) <= 1e-13 * ref
    aK, aH = np.abs(K.astype(LD) / d.astype(LD)[:, None]), np.abs(H.astype(LD) * d.astype(LD)[None, :])
    exact = 1.0 + np.sqrt(float((aK.sum(axis=0) @ aH).max()) * float((aK @ aH.sum(axis=1)).max()))
    assert got >= exact
