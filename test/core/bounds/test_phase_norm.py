"""The per-phase scalar bound's proofs (switchobs_core.bounds.phase_norm) checked in exact rational
arithmetic, and the bound against an error recursion run in extended precision."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.bounds.phase_norm import PhaseNorms, dominates, lyapunov_shapes, verified_factor


def _exact(X: np.ndarray) -> list[list[Fraction]]:
    return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(X)]


def _mul(A, B):
    return [[sum((A[i][k] * B[k][j] for k in range(len(B))), Fraction(0)) for j in range(len(B[0]))]
            for i in range(len(A))]


def _det(A) -> Fraction:
    """Determinant by exact elimination."""
    A = [row[:] for row in A]
    n, det = len(A), Fraction(1)
    for i in range(n):
        p = next((r for r in range(i, n) if A[r][i] != 0), None)
        if p is None:
            return Fraction(0)
        if p != i:
            A[i], A[p] = A[p], A[i]
            det = -det
        det *= A[i][i]
        for r in range(i + 1, n):
            f = A[r][i] / A[i][i]
            for c in range(i, n):
                A[r][c] -= f * A[i][c]
    return det


def _psd_exact(X) -> bool:
    """Every principal minor >= 0 (exact): X is positive semidefinite."""
    n = len(X)
    for k in range(1, n + 1):
        for idx in itertools.combinations(range(n), k):
            if _det([[X[i][j] for j in idx] for i in idx]) < 0:
                return False
    return True


def _spd(rng: np.random.Generator, n: int, spread: float) -> np.ndarray:
    """A symmetric positive definite matrix (exactly symmetric) with eigenvalues over ``spread`` decades."""
    Qo, _ = np.linalg.qr(rng.normal(size=(n, n)))
    P = (Qo * 10.0 ** rng.uniform(-spread, 0, n)) @ Qo.T
    return 0.5 * (P + P.T)


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 4), st.integers(0, 2**31), st.floats(0.0, 6.0), st.booleans())
def test_a_proved_domination_holds_exactly(n, seed, spread, identity):
    """Whenever ``a P >= M Q M'`` is proved, ``a P - M Q M'`` is positive semidefinite in exact
    rational arithmetic (with the inputs as stored), also at ``a`` a hair above the smallest."""
    rng = np.random.default_rng(seed)
    P, Q = _spd(rng, n, spread), _spd(rng, n, spread)
    M = None if identity else rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-2, 2)
    a = verified_factor(P, Q, M)
    assert np.isfinite(a)
    Z = Q if M is None else scipy.linalg.eigh(0.5 * ((M @ Q) @ M.T + ((M @ Q) @ M.T).T), P, eigvals_only=True)
    for cand in (a, float(np.max(Z)) * (1.0 + 1e-9) if M is not None else a * (1.0 + 1e-9)):
        if dominates(cand, P, Q, M):
            Pe, Qe = _exact(P), _exact(Q)
            MQM = Qe if M is None else _mul(_mul(_exact(M), Qe), [list(r) for r in zip(*_exact(M), strict=True)])
            X = [[Fraction(cand) * Pe[i][j] - MQM[i][j] for j in range(n)] for i in range(n)]
            assert _psd_exact(X)


def test_the_proved_factor_is_close_to_the_generalised_eigenvalue():
    """The smallest proved factor is within 1e-5 of lambda_max(M Q M', P) for well-conditioned
    matrices, and a factor 1 % below it is never proved."""
    rng = np.random.default_rng(7)
    for n in (3, 12, 36):
        P, Q = _spd(rng, n, 1.0), _spd(rng, n, 1.0)
        M = rng.normal(size=(n, n))
        Z = (M @ Q) @ M.T
        lam = float(scipy.linalg.eigh(0.5 * (Z + Z.T), P, eigvals_only=True)[-1])
        a = verified_factor(P, Q, M)
        assert lam <= a <= lam * (1.0 + 1e-5)
        assert not dominates(0.99 * lam, P, Q, M)


def test_an_unsymmetric_shape_is_not_proved():
    P = np.array([[2.0, 0.5], [0.5000000001, 2.0]])
    assert not dominates(10.0, P, np.eye(2))


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**31), st.integers(2, 5), st.integers(2, 6))
def test_the_scalar_bound_holds_against_the_error_in_extended_precision(seed, n, N):
    """``e_k = M_j e_{k-1} + r_k`` over a few periods with residuals on the sphere ``||D^-1 r|| = rho``
    and the start on the ellipsoid's boundary, run in long double: ``||e_k|| <= bound`` every step,
    and the bound is not vacuous (within 1e4 of the error's largest possible size when the map
    contracts)."""
    rng = np.random.default_rng(seed)
    d = 2.0 ** rng.integers(-4, 5, n).astype(float)
    maps = []
    for _ in range(N):
        A = rng.normal(size=(n, n))
        A *= 0.9 / max(abs(np.linalg.eigvals(A)))
        maps.append((A / d[None, :]) * d[:, None])      # any units: the balanced map is A
    mono = np.eye(n)
    for j in range(1, N + 1):
        mono = maps[j % N] @ mono
    rate = float(max(abs(np.linalg.eigvals(mono)))) ** (1.0 / N)
    lam = 1.0 - 0.5 * (1.0 - rate)
    pn = PhaseNorms(maps, lyapunov_shapes(maps, d, lam, rounds=6), d)
    assert np.all(np.isfinite(pn.c)) and np.all(np.isfinite(pn.h)) and np.all(np.isfinite(pn.t))
    S0 = np.diag(d * d) * 0.25
    beta = pn.start(S0, 0)
    z = rng.normal(size=n)
    e = (np.sqrt(np.diag(S0)) * z / np.linalg.norm(z)).astype(np.longdouble)   # on E(S0)'s boundary
    Ml = [m.astype(np.longdouble) for m in maps]
    rho = 1e-3
    for k in range(1, 4 * N + 1):
        j = k % N
        r = rng.normal(size=n)
        r = (d * r / np.linalg.norm(r) * rho).astype(np.longdouble)     # ||D^-1 r|| = rho
        e = Ml[j] @ e + r
        beta = pn.step(beta, j, rho)
        assert float(np.sqrt(np.sum(e * e))) <= pn.bound(beta, j)
        assert float(np.sqrt(np.sum((e / d) ** 2))) <= pn.balanced(beta, j)


@settings(max_examples=15, deadline=None)
@given(st.integers(2, 4), st.integers(0, 2**31), st.integers(0, 400))
def test_units_far_apart_are_proved_and_hold_exactly(n, seed, span):
    """States in units ``2^span`` apart (the shapes' diagonals over up to 240 decades): the factor is
    still proved close to the generalised eigenvalue, and the proof holds in exact arithmetic."""
    rng = np.random.default_rng(seed)
    s = 2.0 ** rng.integers(-span // 2, span // 2 + 1, n).astype(float)
    P, Q = _spd(rng, n, 1.0) * np.outer(s, s), _spd(rng, n, 1.0) * np.outer(s, s)
    M = (rng.normal(size=(n, n)) * s[:, None]) / s[None, :]
    Z = (M @ Q) @ M.T
    lam = float(scipy.linalg.eigh(0.5 * (Z + Z.T), P, eigvals_only=True)[-1])
    a = verified_factor(P, Q, M)
    assert a <= lam * (1.0 + 1e-3)
    Pe, Qe, Me = _exact(P), _exact(Q), _exact(M)
    MQM = _mul(_mul(Me, Qe), [list(r) for r in zip(*Me, strict=True)])
    assert _psd_exact([[Fraction(a) * Pe[i][j] - MQM[i][j] for j in range(n)] for i in range(n)])
