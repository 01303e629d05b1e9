"""Orthogonal observability decomposition (Lemma t:decomposition): properties on random systems."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.model import decomposition
from switchobs_core.model.decomposition import canonical_basis, log_norm, observability_decomposition
from switchobs_core.model.scenarios import camera_agents


def random_pair(seed: int, n: int, p: int, r: int, scale_exp: float):
    """A pair (A, C) with a planted unobservable subspace of dimension n - r, rotated by
    a random orthogonal Q, and state scaling diag(10^[-e, e]) (badly scaled when e > 0)."""
    rng = np.random.default_rng(seed)
    Ao = rng.standard_normal((r, r))
    Co = rng.standard_normal((p, r))
    Au = rng.standard_normal((n - r, n - r))
    Auo = rng.standard_normal((n - r, r))
    A = np.block([[Ao, np.zeros((r, n - r))], [Auo, Au]])
    C = np.hstack([Co, np.zeros((p, n - r))])
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    S = np.diag(10.0 ** rng.uniform(-scale_exp, scale_exp, n))
    Si = np.linalg.inv(S)
    # x = Q S z: A_z = S^-1 Q' A Q S, C_z = C Q S
    return Si @ Q.T @ A @ Q @ S, C @ Q @ S


def obsv(A, C):
    return np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(A.shape[0])])


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(2, 9),
    p=st.integers(1, 3),
    data=st.data(),
    scale_exp=st.sampled_from([0.0, 1.0, 2.0]),
)
def test_decomposition_properties(seed, n, p, data, scale_exp):
    r = data.draw(st.integers(1, n))
    A, C = random_pair(seed, n, p, r, scale_exp)
    d = observability_decomposition(A, C)
    T = d.T
    # T orthogonal
    assert np.allclose(T.T @ T, np.eye(n), atol=1e-10)
    scale = max(np.linalg.norm(A, 2), np.linalg.norm(C, 2), 1.0)
    # the zero blocks are zero to tolerance (e:A_obs_decomp, e:C_obs_decomp)
    At = T.T @ A @ T
    assert np.linalg.norm(At[: d.r, d.r :]) <= 1e-7 * scale
    assert np.linalg.norm((C @ T)[:, d.r :]) <= 1e-7 * scale
    # (A_o, C_o) observable: the smallest singular value of its observability matrix is
    # clearly nonzero relative to its norm (not a rank call on a power stack of the big pair)
    O = obsv(d.A_o, d.C_o)
    sv = np.linalg.svd(O, compute_uv=False)
    assert sv[-1] > 1e-12 * sv[0]
    # r equals the rank of the observability matrix where that is well conditioned
    O_full = obsv(A, C)
    s_full = np.linalg.svd(O_full, compute_uv=False)
    gap_ok = s_full[r - 1] > 1e-6 * s_full[0] and (r == n or s_full[r] < 1e-11 * s_full[0])
    if gap_ok:
        assert d.r == r == np.linalg.matrix_rank(O_full, tol=1e-9 * s_full[0])


def test_badly_scaled_system_keeps_structure():
    # States scaled by 1e-3 .. 1e3: the planted r is recovered, blocks are zero.
    A, C = random_pair(7, 8, 2, 5, 3.0)
    d = observability_decomposition(A, C)
    assert d.r == 5
    assert d.residual < 1e-9


def test_canonical_basis_is_basis_independent():
    rng = np.random.default_rng(1)
    V, _ = np.linalg.qr(rng.standard_normal((7, 3)))
    R, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    B1 = canonical_basis(V)
    B2 = canonical_basis(V @ R)
    assert np.allclose(B1, B2, atol=1e-12)
    assert np.allclose(B1.T @ B1, np.eye(3), atol=1e-12)


def test_decomposition_deterministic_under_state_rotation_of_basis(paper):
    # Same subspaces, different input order of an orthonormal basis: identical T.
    d1 = observability_decomposition(paper.A, paper.C[0])
    d2 = observability_decomposition(paper.A, paper.C[0][::-1])  # rows permuted: same ker C
    assert np.array_equal(d1.T, d2.T)
    # For the paper's coordinate-aligned subspaces the canonical basis is the coordinate axes.
    assert np.allclose(np.abs(d1.T_o), np.eye(12)[:, :8])


def test_observable_channel_has_no_unobservable_part():
    A = np.array([[0.0, 1.0], [-2.0, -3.0]])
    d = observability_decomposition(A, [[1.0, 0.0]])
    assert d.r == 2 and d.T_u.shape == (2, 0) and d.observable and d.detectable


def test_log_norm_closed_form():
    M = np.array([[0.0, 1.0], [0.0, 0.2]])
    assert log_norm(M) == pytest.approx(0.1 + np.sqrt(0.01 + 0.25))
    # ||expm(M t)|| <= exp(mu t) (e:exp_bound_mu_p)
    from scipy.linalg import expm

    for t in (0.1, 1.0, 3.0):
        assert np.linalg.norm(expm(M * t), 2) <= np.exp(log_norm(M) * t) * (1 + 1e-12)


def _whole_state(A, C):
    """The decomposition with the subspace iteration on every state (nothing left unreached)."""
    with pytest.MonkeyPatch.context() as m:
        m.setattr(decomposition, "_reached", lambda nz, C: np.arange(nz.shape[0]))
        return observability_decomposition(A, C)


@pytest.mark.parametrize("agents", [2, 3, 32])
def test_decoupled_bodies_give_the_whole_state_doubles(agents):
    """camera_agents (the paper's model at M = 2): each channel reaches the camera and its agent only;
    the decomposition from those 8 states is the whole-state one, bit for bit."""
    system = camera_agents(agents)
    A = np.asarray(system.A)
    for C in system.C:
        fast, whole = observability_decomposition(A, C), _whole_state(A, C)
        R = decomposition._reached(A != 0, C)
        assert R.size == 8
        assert decomposition._reduced(A, C, R, decomposition.DEFAULT_RTOL, float(np.linalg.norm(A, 2))) is not None
        assert fast.r == whole.r == 8 and fast.residual == whole.residual
        for f in ("T", "A_o", "C_o", "A_uo", "A_u"):
            assert np.array_equal(getattr(fast, f), getattr(whole, f)), f


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), blocks=st.lists(st.integers(1, 4), min_size=2, max_size=5),
       data=st.data())
def test_unreached_states_are_unobservable_axes(seed, blocks, data):
    """Decoupled blocks, coordinates shuffled, an output reading some blocks: the states it never reaches
    are unobservable coordinate axes of T_u exactly, and the subspaces, r and the blocks' structure are
    those of the whole-state iteration (to its own accuracy: its residual, at most 1e-9)."""
    rng = np.random.default_rng(seed)
    n = sum(blocks)
    A = np.zeros((n, n))
    start = 0
    for b in blocks:
        A[start:start + b, start:start + b] = rng.standard_normal((b, b))
        start += b
    read = data.draw(st.lists(st.integers(0, len(blocks) - 1), min_size=1, max_size=len(blocks), unique=True))
    C = np.zeros((2, n))
    starts = np.cumsum([0, *blocks])
    for j in read:
        C[:, starts[j]:starts[j + 1]] = rng.standard_normal((2, blocks[j]))
    perm = rng.permutation(n)
    A, C = A[np.ix_(perm, perm)], C[:, perm]
    fast, whole = observability_decomposition(A, C), _whole_state(A, C)
    reached = decomposition._reached(A != 0, C)
    assert set(perm[reached]) <= {i for j in read for i in range(starts[j], starts[j + 1])}
    assert fast.r == whole.r
    tol = 1e-8 + 100 * whole.residual
    for a, b in ((fast.T_o, whole.T_o), (fast.T_u, whole.T_u)):
        assert np.abs(a @ a.T - b @ b.T).max() <= tol
    assert np.abs(fast.T.T @ fast.T - np.eye(n)).max() <= 1e-12
    assert fast.residual <= 1e-9
    r = fast.r          # the blocks rebuild A and C (e:A_obs_decomp, e:C_obs_decomp)
    At = np.block([[fast.A_o, np.zeros((r, n - r))], [fast.A_uo, fast.A_u]])
    scale = max(1.0, np.abs(A).max(), np.abs(C).max())
    assert np.abs(fast.T @ At @ fast.T.T - A).max() <= 10 * n * (1e-15 + fast.residual) * scale
    assert np.abs(fast.C_o @ fast.T_o.T - C).max() <= 10 * n * (1e-15 + fast.residual) * scale
    unreached = np.setdiff1d(np.arange(n), reached)
    for i in unreached:         # e_i is a column of T_u, exactly
        assert any(np.array_equal(col, np.eye(n)[:, i]) for col in fast.T_u.T)


def test_identical_bodies_read_alike_take_the_whole_state_basis():
    """Two identical 2-state bodies read by one output (their pose sum) and an unread state: the rule's
    compression has equal eigenvalues, so its basis depends on how the eigenvalue solver splits them;
    the decomposition is then the whole-state one, bit for bit (a table designed on either path
    matches)."""
    A = np.array([[-0.2277, -1.279, 0, 0.5969, 0], [0, -0.3395, 0, -0.1871, 0], [0, 0, 0.3431, 0, -1.163],
                  [0, -1.163, 0, 0.3431, 0], [0, 0, -0.1871, 0, -0.3395]])
    C = np.array([[0, -1.128, 0.9667, 0.9667, -1.128]])
    R = decomposition._reached(A != 0, C)
    assert R.size == 4
    assert decomposition._reduced(A, C, R, decomposition.DEFAULT_RTOL, float(np.linalg.norm(A, 2))) is None
    fast, whole = observability_decomposition(A, C), _whole_state(A, C)
    assert fast.r == whole.r == 2
    for f in ("T", "A_o", "C_o", "A_uo", "A_u"):
        assert np.array_equal(getattr(fast, f), getattr(whole, f)), f


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), b=st.integers(1, 3), u=st.integers(1, 3))
def test_twin_bodies_with_an_unread_driven_body(seed, b, u):
    """Twin bodies read by their sum (unobservable directions among the reached states) and an unread body
    the first twin drives, coordinates shuffled: r is the whole-state iteration's; where the rule's
    eigenvalues are distinct the reduced decomposition's T is the whole-state one within 1e-12 (its
    unreached states exact axes of T_u), where two are tied it is the whole-state one bit for bit."""
    rng = np.random.default_rng(seed)
    n = 2 * b + u
    Ab = rng.standard_normal((b, b))
    A = np.zeros((n, n))
    A[:b, :b] = A[b:2 * b, b:2 * b] = Ab
    A[2 * b:, 2 * b:] = rng.standard_normal((u, u))
    A[2 * b:, :b] = rng.standard_normal((u, b))
    C = np.zeros((1, n))
    C[0, :b] = C[0, b:2 * b] = rng.standard_normal(b)
    perm = rng.permutation(n)
    A, C = A[np.ix_(perm, perm)], C[:, perm]
    R = decomposition._reached(A != 0, C)
    assert R.size == 2 * b
    fast, whole = observability_decomposition(A, C), _whole_state(A, C)
    assert fast.r == whole.r < R.size
    reduced = decomposition._reduced(A, C, R, decomposition.DEFAULT_RTOL, float(np.linalg.norm(A, 2)))
    if reduced is None:
        assert np.array_equal(fast.T, whole.T)
        return
    assert np.abs(fast.T - whole.T).max() <= 1e-12
    unreached = np.setdiff1d(np.arange(n), R)
    for i in unreached:
        assert any(np.array_equal(col, np.eye(n)[:, i]) for col in fast.T_u.T)
