"""The optional compiled form of :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.step_dense`,
of the amortised read's pass between anchors (:func:`between`) and of a balanced norm (:data:`NORM`,
``norm(x, s) = ||diag(s) x||``, ``s`` None for ``||x||``: its sum of squares in a fixed order, four
lanes, as a numpy dot's in another), of a Kalman sample's estimate through a fused map (:func:`correct`) and of
the exact set's step through a Kalman sample's factored map (:func:`sandwich`: ``Phi~ S Phi~'``, the same doubles
as scipy's sparse products; :func:`factored`: the correction's rank-``2p`` term, ``w`` and the assembly; and
:func:`open_plan`: the O(n) plan of an open-loop prior's set):
``_dense_step.c``, built by
``setup.py`` where a C compiler is found (``scripts/bootstrap.sh`` builds it into the checkout). The
numpy code stays the reference: without the extension, or for arrays the kernel does not take (not
C-ordered doubles), it runs instead. The module carries the SHA-256 of the source it was built from
(``SOURCE_SHA256``, from ``setup.py``); where ``_dense_step.c`` lies beside this file (a checkout) a
module built from another source is refused with a warning (the numpy step runs):
``python -m switchobs_core.numerics.dense_kernel`` exits 1 then (``bootstrap.sh`` rebuilds). The
kernel is x86-64 only (``target_clones``); elsewhere it does not build and the numpy step runs.

The kernel computes the set of ``step_dense``'s docstring with the coefficients the ellipsoid
computed (:attr:`ErrorEllipsoid._aux`: ``1 / d^2``, ``d^2``, the factors ``kW, kR, gsum, k1, k3, kf``,
``a``'s clamp, ``theta``'s and ``c_2``'s factors and ``eta``; ``c_4`` as an argument): every coefficient
of the error analysis has its one owner in :mod:`~switchobs_core.numerics.rounding`), in one call instead
of 17 array operations and the scalar arithmetic between them:
``T = M S`` and ``Z = T M'`` with each entry a dot product summed in index order (within
``gamma_n |a|.|b|`` as any order, the bound the allowance ``gamma_{2n+2}`` is built on), ``Z``
on and above its diagonal and mirrored (exactly symmetric), ``w d = (D |M|) s``, and the diagonal
allowance and trace in the same operations as the numpy step. It is compiled with
``-ffp-contract=off`` (no FMA contraction, no reassociation): every x86-64 CPU gives the same doubles
(its products use AVX2 where the CPU has it and SSE2 elsewhere, elementwise, in the same order).
"""

from __future__ import annotations

import hashlib
import os
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

import numpy as np

#: The kernel's source beside this module (absent from an installed package: the module as built).
SOURCE = Path(__file__).with_name("_dense_step.c")


def built_from(module: ModuleType, source: Path = SOURCE) -> bool:
    """Whether ``module`` was built from ``source`` (its ``SOURCE_SHA256`` is the file's), or ``source``
    is absent; else False with a warning: a stale build (an older source, or another kernel's)."""
    try:
        digest = hashlib.sha256(source.read_bytes()).hexdigest()
    except OSError:
        return True
    if getattr(module, "SOURCE_SHA256", None) == digest:
        return True
    warnings.warn(f"{getattr(module, '__file__', module)} was not built from {source} (a stale build): the "
                  "numpy step runs; rebuild it (scripts/bootstrap.sh)", RuntimeWarning, stacklevel=2)
    return False


try:
    from . import _dense_step
except ImportError:     # not built (no compiler, not x86-64), or built for another Python: the numpy step
    _dense_step = None
if _dense_step is not None and built_from(_dense_step):
    STEP, BETWEEN, NORM = _dense_step.step, _dense_step.between, _dense_step.norm
    CORRECT, ABSROWS = _dense_step.correct, _dense_step.absrows
    SANDWICH, FACTORED, OPEN_PLAN = _dense_step.sandwich, _dense_step.factored, _dense_step.open_plan
    BLOCK, KAPPA = _dense_step.block, _dense_step.kappa
else:
    STEP = BETWEEN = NORM = CORRECT = ABSROWS = SANDWICH = FACTORED = OPEN_PLAN = BLOCK = KAPPA = None

#: Calls the kernel refused (an array not C-ordered doubles of the right shape, an output sharing memory
#: with an input) and numpy computed instead, by function: read by benchmarks and tests.
FALLBACKS = {"step": 0, "between": 0, "correct": 0, "sandwich": 0, "factored": 0, "open_plan": 0, "block": 0,
             "kappa": 0}

#: Set (to anything but empty or 0) by ``scripts/test.sh``: the test that the kernel is built fails
#: without it, so a test run cannot pass on the numpy step alone unnoticed.
REQUIRE_ENV = "SWITCHOBS_REQUIRE_KERNEL"

__all__ = ["STEP", "BETWEEN", "NORM", "CORRECT", "ABSROWS", "SANDWICH", "FACTORED", "OPEN_PLAN", "BLOCK", "KAPPA",
           "FALLBACKS", "REQUIRE_ENV", "SOURCE", "available", "built_from", "required", "numpy_step", "numpy_factored",
           "step", "between", "correct", "sandwich", "factored", "open_plan", "block", "kappa"]


def available() -> bool:
    """Whether the compiled kernel is importable (and used by ``step_dense``)."""
    return STEP is not None


def required() -> bool:
    """Whether the environment asks for the kernel (:data:`REQUIRE_ENV`)."""
    return os.environ.get(REQUIRE_ENV, "") not in ("", "0")


@contextmanager
def numpy_step() -> Iterator[None]:
    """``step_dense`` in numpy within the block (the kernel set aside): the reference path, for tests
    and benchmarks where the kernel is built."""
    global STEP
    kept, STEP = STEP, None
    try:
        yield
    finally:
        STEP = kept


@contextmanager
def numpy_factored() -> Iterator[None]:
    """The sparse maps' sets (:func:`sandwich`, :func:`factored`, :func:`open_plan`, :func:`block`, :func:`kappa`) in
    numpy inside the ``with``: the reference path, for tests and benchmarks where the kernel is built."""
    global SANDWICH, FACTORED, OPEN_PLAN, BLOCK, KAPPA
    kept = SANDWICH, FACTORED, OPEN_PLAN, BLOCK, KAPPA
    SANDWICH = FACTORED = OPEN_PLAN = BLOCK = KAPPA = None
    try:
        yield
    finally:
        SANDWICH, FACTORED, OPEN_PLAN, BLOCK, KAPPA = kept


def step(M: np.ndarray, S: np.ndarray, aMd: np.ndarray, aux: np.ndarray, rho: float,
         c4: float) -> tuple[np.ndarray, float, float, float, float] | None:
    """``(S', tr, ls, alpha, theta)`` of ``step_dense`` by the kernel (``S'`` a new array, ``tr`` its trace
    and ``ls`` its balanced trace ``ErrorEllipsoid.lam_scaled``, each summed in index order and rounded
    up; ``alpha, theta`` the outer sum's factors, for the caller's overflow guard), or
    None where it does not apply (no kernel, an array not C-ordered doubles of the right size): the
    caller steps in numpy."""
    if STEP is None:
        return None
    out = np.empty(S.shape)
    try:
        tr, ls, alpha, theta = STEP(M, S, aMd, aux, out, rho, c4)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["step"] += 1
        return None
    return out, tr, ls, alpha, theta


def between(S: np.ndarray, Sa: np.ndarray, va: np.ndarray, theta_a: float,
            D: np.ndarray) -> tuple[np.ndarray, float, float, float] | None:
    """``(w, c, ||w||, ||D||_F)`` of :class:`~switchobs_core.bounds.read.AnchoredBound`'s read between
    anchors by the kernel: ``w = S v_a``, ``c = v_a' w / theta_a`` and, where ``c`` is finite and
    ``>= 0``, ``D = fl(S - fl(c S_a))`` written into ``D`` with its Frobenius norm (else nan); every
    sum in a fixed order (four lanes), as that module's step 3 allows. None where the kernel does
    not apply: the caller computes them in numpy."""
    if BETWEEN is None:
        return None
    w = np.empty(va.shape)
    try:
        c, nw, fd = BETWEEN(S, Sa, va, theta_a, w, D)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["between"] += 1
        return None
    return w, c, nw, fd


def correct(Phi: np.ndarray, H: np.ndarray, K: np.ndarray, x0: np.ndarray,
            y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(x^-, nu, x^+)`` with ``x^- = Phi x0``, ``nu = y - H x^-`` and ``x^+ = x^- + K nu`` (new arrays) by the
    kernel, each entry a dot product in a fixed order (four lanes; within ``gamma_n |a|.|b|`` as any
    order), or None where it does not apply (no kernel, arrays not C-ordered doubles of matching sizes):
    the caller computes them in numpy."""
    if CORRECT is None:
        return None
    xm, nu, xp = np.empty(x0.shape), np.empty(y.shape), np.empty(x0.shape)
    try:
        CORRECT(Phi, H, K, x0, y, xm, nu, xp)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["correct"] += 1
        return None
    return xm, nu, xp


def sandwich(ip: np.ndarray, ix: np.ndarray, dv: np.ndarray, T: np.ndarray, X: np.ndarray) -> np.ndarray | None:
    """``Phi~ T' Phi~'`` (a new C-ordered array) for ``Phi~`` in compressed rows (``ip``, ``ix`` as ``np.intp``,
    ``dv`` its values) and a C-ordered ``T``, with ``X`` (C-ordered n x n, apart from ``T``) as scratch: the
    doubles of :meth:`~switchobs_core.bounds.kalman_map.SparseTransition.sandwich_either`'s two products
    (each entry ``0.0`` plus the row's terms in stored order, as scipy's ``csr_matvecs``). None where the
    kernel does not apply: the caller computes it in numpy."""
    if SANDWICH is None:
        return None
    Y = np.empty(T.shape)
    try:
        SANDWICH(ip, ix, dv, T, X, Y)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["sandwich"] += 1
        return None
    return Y


def factored(Y: np.ndarray, S: np.ndarray, ip: np.ndarray, ix: np.ndarray, adv: np.ndarray, K: np.ndarray,
             hp: np.ndarray, hj: np.ndarray, hv: np.ndarray, aux: np.ndarray, rho: float, wf: float, czp: float,
             c1f: float, c4f: float, mn: float) -> tuple[float, float, float, float] | None:
    """``(tr, ls, alpha, theta)`` of :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.step_factored` by the
    kernel, the new set written over ``Y``; None (``Y`` untouched) where the kernel does not apply (not built,
    arrays not C-ordered doubles and ``np.intp`` indices of matching sizes, ``Y`` sharing memory with an input)."""
    if FACTORED is None:
        return None
    try:
        return FACTORED(Y, S, ip, ix, adv, K, hp, hj, hv, aux, rho, wf, czp, c1f, c4f, mn)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["factored"] += 1
        return None


def open_plan(Z: np.ndarray, S: np.ndarray, ip: np.ndarray, ix: np.ndarray, adv: np.ndarray, aux: np.ndarray,
              rho: float, wf: float, czp: float, c1f: float, c4f: float,
              mn: float) -> tuple[np.ndarray, float, float, float, float] | None:
    """``(q, alpha, theta, trace, tr)`` of :meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid.pending_open` by
    the kernel (``q`` a new array), or None where it does not apply: the caller plans in numpy."""
    if OPEN_PLAN is None:
        return None
    q = np.empty(Z.shape[0])
    try:
        alpha, theta, trace, tr = OPEN_PLAN(Z, S, ip, ix, adv, aux, q, rho, wf, czp, c1f, c4f, mn)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["open_plan"] += 1
        return None
    return q, alpha, theta, trace, tr


def block(Z: np.ndarray, cols: np.ndarray, ha: float, q: np.ndarray) -> np.ndarray | None:
    """``((Z + Z') ha + diag(q))[np.ix_(cols, cols)]`` (a new array) by the kernel, numpy's operations in its order
    (:meth:`~switchobs_core.numerics.rounding.ErrorEllipsoid._block`: the same doubles), or None where it does not
    apply (``cols`` not ``np.intp``, ``q`` not C-ordered doubles): the caller takes numpy's path."""
    if BLOCK is None:
        return None
    B = np.empty((cols.size, cols.size))
    try:
        BLOCK(Z, cols, ha, q, B)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["block"] += 1
        return None
    return B


def kappa(K: np.ndarray, H: np.ndarray, d: np.ndarray) -> tuple[float, float] | None:
    """``(||.||_1, ||.||_inf)`` of ``|D^-1 K| |H D|`` by the kernel (:attr:`~switchobs_core.bounds.kalman_map.
    KalmanMap.kappa`'s sums, in index order), or None where it does not apply (arrays not C-ordered doubles of
    matching sizes): the caller computes them in numpy."""
    if KAPPA is None:
        return None
    try:
        return KAPPA(K, H, d)
    except (BufferError, ValueError, TypeError):
        FALLBACKS["kappa"] += 1
        return None


if __name__ == "__main__":      # exit 0 where the kernel is built from the source beside it (bootstrap.sh)
    sys.exit(0 if available() else 1)
