"""The compiled dense step (:mod:`switchobs_core.numerics.dense_kernel`, ``_dense_step.c``) against the
numpy ``ErrorEllipsoid.step_dense`` (the reference): the same set up to the rounding of ``M S M'`` and
the allowances (``_dense_cases.allowance_ratio``; for its well-conditioned cases within 1e-13 of each
entry relative to the diagonal, not in general: ``test_step_dense``'s rank-one case), the same trace,
exactly symmetric, its products the index-order sums its source states (bit for bit), containing ``M S
M'`` computed in extended precision (hypothesis over n = 1..64, the stack's last size 40 and the heap's
first 41, units and scales 1e-30..1e30); every coefficient from Python; a stale build refused; bad
arguments raise; arrays the kernel does not take fall back to numpy. ``scripts/test.sh`` asks for the
kernel (``SWITCHOBS_REQUIRE_KERNEL``): there the first test fails if it is not built."""

from __future__ import annotations

import ast
import hashlib
import math
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _dense_cases import allowance_ratio, pair
from hypothesis import example, given, settings
from hypothesis import strategies as st

from switchobs_core.numerics import dense_kernel
from switchobs_core.numerics.dense_kernel import numpy_step
from switchobs_core.numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid

LD = np.longdouble
#: The two steps round the same quantities in another order (BLAS against index order, the kernel's
#: ``alpha Z`` against numpy's ``(Z + Z') alpha / 2``): for :func:`pair`'s well-conditioned cases a few
#: ``u`` of ``sqrt(S_ii S_jj)`` each (1e-13 is about 450 ``u``); in general within the allowance.
RTOL = 1e-13

needs_kernel = pytest.mark.skipif(not dense_kernel.available(), reason="the compiled kernel is not built")


def test_kernel_is_built_where_asked_for():
    """Under ``scripts/test.sh`` (``SWITCHOBS_REQUIRE_KERNEL=1``) the kernel must be importable."""
    if not dense_kernel.required():
        pytest.skip(f"{dense_kernel.REQUIRE_ENV} not set")
    assert dense_kernel.available(), "switchobs_core/numerics/_dense_step.c is not built (scripts/bootstrap.sh)"


ROOT = Path(__file__).resolve().parents[3]


@needs_kernel
def test_the_kernel_is_built_from_the_source_beside_it():
    """The module carries its source's SHA-256 (setup.py); ``python -m ...dense_kernel`` (bootstrap.sh's
    check) exits 0 for it."""
    assert dense_kernel._dense_step.SOURCE_SHA256 == hashlib.sha256(dense_kernel.SOURCE.read_bytes()).hexdigest()
    run = subprocess.run([sys.executable, "-m", "switchobs_core.numerics.dense_kernel"], cwd=ROOT)
    assert run.returncode == 0


def test_a_module_built_from_another_source_is_refused(tmp_path):
    """A stale build (an older source, or one with the same names and other arithmetic): refused with a
    warning; without the source beside it (an installed package) the module is taken as built."""
    src = tmp_path / "_dense_step.c"
    src.write_bytes(b"/* the kernel */")
    good = SimpleNamespace(SOURCE_SHA256=hashlib.sha256(b"/* the kernel */").hexdigest(), __file__="k.so")
    assert dense_kernel.built_from(good, src)
    for stale in (SimpleNamespace(SOURCE_SHA256="0" * 64, __file__="k.so"), SimpleNamespace(__file__="k.so")):
        with pytest.warns(RuntimeWarning, match="not built from"):
            assert not dense_kernel.built_from(stale, src)
        assert dense_kernel.built_from(stale, tmp_path / "absent.c")


def _kernel_flags() -> list[str]:
    """setup.py's ``KERNEL_FLAGS`` (read from its source: importing it would run ``setup()``)."""
    for node in ast.parse((ROOT / "setup.py").read_text()).body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "KERNEL_FLAGS":
            return ast.literal_eval(node.value)
    raise AssertionError("setup.py has no KERNEL_FLAGS")


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.parametrize("env_flags", [["-ffast-math"], ["-ffinite-math-only"], ["-O3", "-ffast-math"]])
def test_fast_math_from_the_environment_is_undone_or_refused(env_flags):
    """The environment's CFLAGS come first on the compiler's command line, setup.py's flags after: with
    them the source preprocesses (IEEE arithmetic restored); without them it refuses to compile (its
    ``#error``), so a fast-math kernel is never built (the numpy step runs)."""
    src = ROOT / "switchobs_core" / "numerics" / "_dense_step.c"
    cmd = ["cc", "-E", "-o", "/dev/null", "-I", sysconfig.get_paths()["include"], str(src)]

    def rc(flags):
        return subprocess.run(cmd[:1] + flags + cmd[1:], capture_output=True, text=True).returncode
    assert rc([]) == 0
    assert rc(env_flags) != 0
    assert rc(env_flags + _kernel_flags()) == 0


def _stepped(M, S, d, rho, absM, kernel: bool) -> ErrorEllipsoid:
    n = M.shape[0]
    ell = ErrorEllipsoid(n, 1.0, d)
    ell.S, ell.tr = S.copy(), float(np.trace(S)) * (1 + 4 * n * UNIT_ROUNDOFF)
    if kernel:
        ell.step_dense(M, absM, rho)
    else:
        with numpy_step():
            ell.step_dense(M, absM, rho)
    return ell


def _abs(M, d):
    aM = np.abs(M)
    out = (aM, float(aM.sum(axis=1).max()))
    return out if d is None else out + (aM * d[:, None],)


@needs_kernel
@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 64), units=st.booleans(), scale=st.floats(1e-30, 1e30),
       rho=st.sampled_from([0.0, 1e-300, 1e-16, 1e-9, 1e-3, 10.0]), with_dM=st.booleans())
@example(seed=1, n=40, units=True, scale=1.0, rho=1e-9, with_dM=True)       # the last size on the stack
@example(seed=2, n=41, units=False, scale=1e10, rho=0.0, with_dM=False)    # the first on the heap
def test_kernel_is_the_numpy_step(seed, n, units, scale, rho, with_dM):
    M, S, d = pair(seed, n, units, scale)
    absM = _abs(M, d if with_dM else None)
    ref, ker = _stepped(M, S, d, rho, absM, False), _stepped(M, S, d, rho, absM, True)
    R, K = ref.S, ker.S
    np.testing.assert_array_equal(K, K.T)                   # exactly symmetric
    if rho == 0.0:
        assert allowance_ratio(K, R, M, S) <= 1.0
    r = np.sqrt(np.outer(np.diagonal(R), np.diagonal(R)))
    assert np.all(np.abs(K - R) <= RTOL * r), float(np.max(np.abs(K - R) / r))
    assert abs(ker.tr - ref.tr) <= RTOL * ref.tr
    assert ker.tr >= float(np.trace(K))
    assert ker.symmetric is K                                    # read without the symmetrisation, as numpy's
    ls, exact = ker.lam_scaled(), float(np.sum(np.diagonal(K).astype(LD) * ker._id2.astype(LD)))
    assert exact <= ls and abs(ls - ref.lam_scaled()) <= RTOL * ref.lam_scaled()   # the kernel's, kept
    assert ls == ErrorEllipsoid.lam_scaled(ker, K) or abs(ls / ErrorEllipsoid.lam_scaled(ker, K) - 1) < 1e-14
    assert abs(ker.bound() - ref.bound()) <= 1e-12 * ref.bound()


@needs_kernel
@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 64), units=st.booleans(), scale=st.floats(1e-30, 1e30),
       rho=st.sampled_from([0.0, 1e-12]))
@example(seed=3, n=40, units=True, scale=1e-20, rho=1e-12)
@example(seed=4, n=41, units=True, scale=1e20, rho=0.0)
def test_kernel_set_contains_the_exact_product(seed, n, units, scale, rho):
    """``S' - M S M'`` (the product in extended precision) is positive semidefinite, checked on its
    diagonal-scaled form; its diagonal is nonnegative exactly (sharp: fails without the allowance)."""
    M, S, d = pair(seed, n, units, scale)
    ell = _stepped(M, S, d, rho, _abs(M, d), True)
    T = M.astype(LD) @ S.astype(LD) @ M.T.astype(LD)
    Dm = ell.S.astype(LD) - T
    assert np.all(np.diagonal(Dm) >= 0), float(np.min(np.diagonal(Dm)))
    r = np.sqrt(np.abs(np.diagonal(ell.S))) + 1e-300
    X = (Dm / np.outer(r, r).astype(LD)).astype(float)
    X = 0.5 * (X + X.T)
    assert float(np.linalg.eigvalsh(X)[0]) >= -1e-12


def _index_order(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A B`` with each entry ``sum_j A_ij B_jk`` summed in the order of ``j``, every product and sum one
    rounding (elementwise numpy operations: no FMA, no reassociation)."""
    C = A[:, :1] * B[:1, :]
    for j in range(1, A.shape[1]):
        C = C + A[:, j:j + 1] * B[j:j + 1, :]
    return C


@needs_kernel
@pytest.mark.parametrize("n", [*range(1, 20), 36, 41])
def test_kernel_products_are_sums_in_index_order(n):
    """The entries of ``Z = (M S) M'`` are the dot products summed in the order of ``j``, as the kernel's
    source states (blocks of rows and columns in registers change nothing of it): with ``rho = 0``
    (``alpha = 1``) the off-diagonal entries of the new set are exactly those doubles, for every split of
    n into the kernel's blocks (4 rows: 8 and 4 columns, then the last 1-3 columns row by row; the
    leftover rows: 2 and 1 columns; the stack and the heap)."""
    M, S, d = pair(n, n, False, 1.0)
    ell = _stepped(M, S, d, 0.0, _abs(M, d), True)
    Z = _index_order(_index_order(M, S), M.T)
    iu = np.triu_indices(n, 1)
    assert np.array_equal(ell.S[iu], Z[iu])
    assert np.array_equal(ell.S.T[iu], Z[iu])


@needs_kernel
def test_kernel_gives_the_same_doubles_on_every_call():
    """The kernel's arithmetic is fixed (no threads, no reassociation): two calls, the same doubles."""
    M, S, d = pair(5, 36, True, 1.0)
    a, b = (_stepped(M, S, d, 1e-9, _abs(M, d), True) for _ in range(2))
    assert np.array_equal(a.S, b.S) and a.tr == b.tr


@needs_kernel
def test_arrays_the_kernel_does_not_take_fall_back_to_numpy():
    """An ``S`` not C-ordered (a transposed view) or a map of another type: the numpy step, the same set."""
    M, S, d = pair(2, 7, True, 1.0)
    absM = _abs(M, d)
    ref = _stepped(M, S, d, 1e-6, absM, False)
    ell = ErrorEllipsoid(7, 1.0, d)
    ell.S, ell.tr = np.asfortranarray(S), float(np.trace(S)) * (1 + 28 * UNIT_ROUNDOFF)
    assert not ell.S.flags.c_contiguous
    assert dense_kernel.step(M, ell.S, absM[2], ell._aux, 1e-6, absM[1]) is None
    ell.step_dense(M, absM, 1e-6)
    np.testing.assert_allclose(ell.S, ref.S, rtol=1e-15, atol=0)
    before = dense_kernel.FALLBACKS["step"]
    assert dense_kernel.step(M.astype(np.float32), S, absM[2], ell._aux, 1e-6, absM[1]) is None
    assert dense_kernel.step(M, S, absM[2], ell._aux[:-1], 1e-6, absM[1]) is None
    assert dense_kernel.step(M.ravel(), S, absM[2], ell._aux, 1e-6, absM[1]) is None       # n^2 doubles, 1-D
    assert dense_kernel.FALLBACKS["step"] == before + 3
    with pytest.raises(ValueError, match="shares memory"):      # the output over an input
        dense_kernel.STEP(M, S, absM[2], ell._aux, S, 1e-6, 1.0)
    w, D = np.empty(7), np.empty((7, 7))
    with pytest.raises(ValueError, match="shares memory"):
        dense_kernel.BETWEEN(S, S, D[0], 1.0, w, D)
    with pytest.raises(ValueError, match="wrong shape"):
        dense_kernel.BETWEEN(S, S.reshape(49, 1), w, 1.0, np.empty(7), D)


@needs_kernel
@pytest.mark.parametrize("rho", [math.nan, -1.0])
def test_kernel_takes_a_residual_that_bounds_nothing_as_infinite(rho):
    """Called directly (not through ``step_dense``, which does the same first): the set is not finite."""
    M, S, d = pair(4, 5, True, 1.0)
    ell = ErrorEllipsoid(5, 1.0, d)
    out = np.empty((5, 5))
    tr, ls = dense_kernel.STEP(M, S, np.abs(M) * d[:, None], ell._aux, out, rho, 1.0)[:2]
    assert tr == math.inf and ls == math.inf and np.isinf(np.diagonal(out)).all()


@needs_kernel
@pytest.mark.parametrize("name, value", [("_KTH", 3.0), ("_K2", 5.0), ("_ALO", 0.5), ("_AHI", 1e-8)])
def test_kernel_follows_the_python_coefficients(monkeypatch, name, value):
    """Each coefficient of the error analysis has one owner (``rounding``): changed there, the kernel's set
    follows numpy's (both move away from the set of the unchanged coefficient)."""
    from switchobs_core.numerics import rounding

    M, S, d = pair(11, 7, True, 1.0)
    absM = _abs(M, d)
    before = _stepped(M, S, d, 1e-3, absM, False).S
    monkeypatch.setattr(rounding, name, value)
    ref, ker = _stepped(M, S, d, 1e-3, absM, False).S, _stepped(M, S, d, 1e-3, absM, True).S
    r = np.sqrt(np.outer(np.diagonal(ref), np.diagonal(ref)))
    assert np.max(np.abs(ref - before) / r) > 1e-6              # the change matters
    assert np.all(np.abs(ker - ref) <= RTOL * r), float(np.max(np.abs(ker - ref) / r))


@needs_kernel
def test_a_bad_scalar_argument_raises_before_the_next_is_read():
    """A ``rho`` that is not a number raises its own TypeError; ``mn`` is not converted (no Python code
    runs with an exception pending, no value stands for the failed one)."""
    n = 3
    M, aux, out = np.eye(n), np.ones(2 * n + 11), np.empty((n, n))
    converted = []

    class Mn:
        def __float__(self):
            converted.append(1)
            return 1.0
    with pytest.raises(TypeError, match="must be real number"):
        dense_kernel.STEP(M, M, M, aux, out, "x", Mn())
    assert converted == []
    with pytest.raises(TypeError, match="must be real number"):
        dense_kernel.STEP(M, M, M, aux, out, 0.0, None)


@needs_kernel
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 39), scale=st.floats(1e-30, 1e30),
       drift=st.floats(0.0, 0.2), fortran=st.booleans())
@example(seed=8750382, n=2, scale=5.0, drift=0.0, fortran=False)   # D all cancellation: c's difference shows
def test_kernel_read_pass_is_the_numpy_pass(seed, n, scale, drift, fortran):
    """The amortised read's pass between anchors (``bounds.read``): ``w``, ``c``, ``||w||`` and ``||D||_F``
    within a few ``u`` of numpy's, ``D`` within ``u`` of each entry's scale; an ``S`` not C-ordered is
    numpy's alone."""
    from switchobs_core.bounds.read import _between

    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, n))
    Sa = scale * (X @ X.T / n + 1e-3 * np.eye(n))
    S = Sa * (1.0 + drift) + drift * scale * np.diag(rng.uniform(0, 1, n))
    if fortran:
        S = np.asfortranarray(S)
    va = rng.standard_normal(n)
    va /= np.linalg.norm(va)
    theta = float(va @ Sa @ va)
    Dk, Dn = np.empty((n, n)), np.empty((n, n))
    got = dense_kernel.between(S, Sa, va, theta, Dk)
    ref = _between(S, Sa, va, theta, Dn)
    if not S.flags.c_contiguous:       # (n = 1 is both)
        assert got is None
        return
    w, c, nw, fd = got
    assert np.all(np.abs(w - ref[0]) <= 1e-13 * (np.abs(S) @ np.abs(va)))
    assert abs(c - ref[1]) <= 1e-13 * abs(ref[1]) and abs(nw - ref[2]) <= 1e-13 * ref[2]
    # D = S - c Sa with each side's c (within a few u of each other): their difference times |Sa|, and u
    # of each entry's scale for the rounding of c Sa and of the difference
    assert np.all(np.abs(Dk - Dn) <= abs(c - ref[1]) * np.abs(Sa) + 4 * UNIT_ROUNDOFF * (np.abs(S) + c * np.abs(Sa)))
    assert abs(fd - ref[3]) <= 1e-13 * ref[3] + abs(c - ref[1]) * float(np.linalg.norm(Sa)) \
        + 4 * UNIT_ROUNDOFF * float(np.linalg.norm(np.abs(S) + c * np.abs(Sa)))


@needs_kernel
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(0, 140), scale=st.floats(1e-150, 1e150), scaled=st.booleans())
def test_kernel_norm_is_numpys(seed, n, scale, scaled):
    """``norm(x, s) = ||diag(s) x||`` within ``(n + 2) u`` of numpy's (both sums of squares, in other orders);
    a vector not C-ordered is refused (the caller takes numpy's)."""
    rng = np.random.default_rng(seed)
    x = scale * rng.standard_normal(n)
    s = np.ldexp(1.0, rng.integers(-12, 12, n)) if scaled else None
    v = x if s is None else x * s
    ref = math.sqrt(float(v.dot(v)))
    got = dense_kernel.NORM(x, s)
    assert abs(got - ref) <= (n + 2) * UNIT_ROUNDOFF * ref
    with pytest.raises((BufferError, ValueError)):
        dense_kernel.NORM(np.repeat(x, 2)[::2], None) if n > 1 else dense_kernel.NORM(np.ones(n, np.float32), None)


@needs_kernel
@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 60), p=st.integers(1, 12), scale=st.floats(1e-100, 1e100))
def test_kernel_correction_is_the_numpy_correction(seed, n, p, scale):
    """``correct``: ``x^- = Phi x0``, ``nu = y - H x^-``, ``x^+ = x^- + K nu`` within ``gamma`` of each dot
    product's ``|a|.|b|`` (computed in extended precision) of the exact values from the computed inputs;
    arrays not C-ordered are refused (``KalmanMap.correct`` takes numpy's, with a C-ordered copy kept)."""
    from switchobs_core.bounds.kalman_map import KalmanMap

    rng = np.random.default_rng(seed)
    Phi, H, K = rng.standard_normal((n, n)), rng.standard_normal((p, n)), rng.standard_normal((n, p))
    x0, y = scale * rng.standard_normal(n), scale * rng.standard_normal(p)
    xm, nu, xp = dense_kernel.correct(Phi, H, K, x0, y)
    g = lambda m: 1.01 * m * UNIT_ROUNDOFF / (1 - m * UNIT_ROUNDOFF)
    L = lambda a: a.astype(LD)
    assert np.all(np.abs(L(xm) - L(Phi) @ L(x0)) <= g(n + 1) * (np.abs(L(Phi)) @ np.abs(L(x0))))
    assert np.all(np.abs(L(nu) - (L(y) - L(H) @ L(xm))) <= g(n + 2) * (np.abs(L(y)) + np.abs(L(H)) @ np.abs(L(xm))))
    assert np.all(np.abs(L(xp) - (L(xm) + L(K) @ L(nu))) <= g(p + 2) * (np.abs(L(xm)) + np.abs(L(K)) @ np.abs(L(nu))))
    assert dense_kernel.correct(Phi, H, np.asfortranarray(K), x0, y) is None or p == 1 or n == 1
    assert dense_kernel.correct(Phi, H, K, x0, y[:-1]) is None if p > 1 else True

    m = KalmanMap(SimpleNamespace(Phi=Phi), np.asfortranarray(K), H, np.eye(n))
    km, knu, kp = m.correct(x0, y)
    assert np.array_equal(km, xm) and np.array_equal(knu, nu) and np.array_equal(kp, xp)
    kept = dense_kernel.CORRECT
    dense_kernel.CORRECT = None
    try:
        nm, nnu, npl = m.correct(x0, y)
    finally:
        dense_kernel.CORRECT = kept
    tol = 1e-12 * (np.abs(Phi) @ np.abs(x0) + 1e-300)
    assert np.all(np.abs(nm - xm) <= tol)


@needs_kernel
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 60), scale=st.floats(1e-150, 1e150), nan=st.booleans())
def test_kernel_largest_absolute_row_sum_is_numpys(seed, n, scale, nan):
    """``absrows(D, n)``: the largest ``sum_j |D_ij|`` within ``n u`` of numpy's (other orders of the same
    sums); NaN where a row holds one; ``D`` is not changed; a wrong size is refused."""
    rng = np.random.default_rng(seed)
    D = scale * rng.standard_normal((n, n))
    if nan:
        D[rng.integers(n), rng.integers(n)] = math.nan
    kept = D.copy()
    got = dense_kernel.ABSROWS(D, n)
    ref = float(np.abs(D).sum(axis=1).max())
    assert np.array_equal(D, kept, equal_nan=True)
    if nan:
        assert math.isnan(got)
    else:
        assert abs(got - ref) <= n * UNIT_ROUNDOFF * ref
    with pytest.raises(ValueError):
        dense_kernel.ABSROWS(D, n + 1)


@pytest.mark.skipif(not dense_kernel.available(), reason="the compiled kernel is not built")
def test_kernel_correction_refuses_an_output_on_an_input():
    """``correct`` writes x^-, nu and x^+ while it reads Phi, H, K, x0 and y: an output sharing memory with
    any other buffer is a ValueError (the wrapper's fresh outputs are taken)."""
    Phi, H, K = np.eye(2), np.ones((1, 2)), np.ones((2, 1))
    x0, y = np.array([1.0, 2.0]), np.array([1.0])
    xm, nu, xp = dense_kernel.correct(Phi, H, K, x0, y)
    assert np.array_equal(xm, x0) and np.array_equal(nu, [-2.0]) and np.array_equal(xp, [-1.0, 0.0])
    for args in ((x0, np.empty(1), np.empty(2)), (np.empty(2), y, np.empty(2)), (np.empty(2), np.empty(1), Phi[0]),
                 (xp, np.empty(1), xp)):
        with pytest.raises(ValueError, match="shares memory"):
            dense_kernel.CORRECT(Phi, H, K, x0, y, *args)
