"""System model, scenarios and assumption A1."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.exceptions import InvalidSystem, SwitchobsError, UnobservableSystem
from switchobs_core.model.scenarios import camera_agents, load_system
from switchobs_core.model.system import LTISystem


def obsv_rank(A, C):
    n = A.shape[0]
    O = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(n)])
    return np.linalg.matrix_rank(O)


def test_paper_model_dimensions(paper):
    # Sec. subsec:sim_model: rank O(A, C_i) = 8 < 12, rank O(A, C) = 12.
    assert paper.n == 12 and paper.N == 2 and paper.p == (4, 4)
    info = paper.channels()
    assert [c.r for c in info] == [8, 8]
    assert obsv_rank(paper.A, paper.C_stacked) == 12
    # Each channel alone is neither observable nor detectable (the unobservable agent has
    # an unstable mode 0.1 or 0.2).
    assert not any(c.observable or c.detectable for c in info)
    assert max(z.real for z in info[0].unobservable_eigenvalues) == pytest.approx(0.1)
    assert max(z.real for z in info[1].unobservable_eigenvalues) == pytest.approx(0.2)


def test_paper_mu_values(paper):
    # Sec. subsec:sim_gain: mu1 = 0.6099, mu2 = 0.5525 (4 decimals); closed form
    # d/2 + sqrt(d^2/4 + 1/4) of the 2x2 symmetric part [[0, 1/2], [1/2, d]].
    mu = [c.mu for c in paper.channels()]
    assert round(mu[0], 4) == 0.6099 and round(mu[1], 4) == 0.5525
    for m, d in zip(mu, (0.2, 0.1)):
        assert m == pytest.approx(d / 2 + np.sqrt(d * d / 4 + 0.25), abs=1e-12)


def test_paper_matrices_match_paper_text(paper):
    # e:sim_Aj: A_j = [[0, I], [0, D_j]]; C_rho selects camera and agent-rho positions.
    A = paper.A
    assert A[0, 2] == A[1, 3] == 1 and A[2, 2] == A[3, 3] == 0
    assert A[7, 7] == 0.2 and A[11, 11] == 0.1 and A[6, 6] == A[10, 10] == 0
    assert np.count_nonzero(A) == 3 * 2 + 2  # two ones per body, two positive D entries
    for rho, Ci in enumerate(paper.C, start=1):
        cols = np.nonzero(Ci)[1]
        assert sorted(cols) == [0, 1, 4 * rho, 4 * rho + 1]
    assert paper.state_labels[4] == "agent1.p_x" and paper.state_labels[-1] == "agent2.v_y"


def test_alpha_is_one_for_paper(paper):
    # Theorem t:xtilde_bound: alpha = 1/sigma_min([T_1o'; T_2o']) >= 1. For the paper's
    # coordinate-aligned subspaces every state is seen at least once: alpha = 1.
    assert paper.alpha == pytest.approx(1.0)


@pytest.mark.parametrize("M", [2, 3, 5])
def test_camera_agents_generalisation(M):
    s = camera_agents(M)
    assert s.n == 4 * (M + 1) and s.N == M
    assert [c.r for c in s.channels()] == [8] * M
    assert obsv_rank(s.A, s.C_stacked) == s.n


def test_unobservable_stack_names_directions_and_modes():
    # Two channels that both miss x3, which has an unstable mode 0.5.
    A = np.diag([-1.0, -2.0, 0.5])
    with pytest.raises(UnobservableSystem, match=r"x2.*Unobservable mode\(s\): 0\.5") as exc:
        LTISystem(A, None, [[[1, 0, 0]], [[0, 1, 0]]])
    assert isinstance(exc.value, SwitchobsError) and isinstance(exc.value, ValueError)


@pytest.mark.parametrize(
    "A, C, match",
    [
        ([[0.0, 1.0], [0.0, np.nan]], [[[1, 0]], [[0, 1]]], r"A has a non-finite entry \(nan\) at row 1, column 1"),
        ([[0.0, 1.0], [0.0, np.inf]], [[[1, 0]], [[0, 1]]], "A has a non-finite entry"),
        ([[0.0, 1.0]], [[[1, 0]], [[0, 1]]], "A must be square"),
        (np.eye(2), [[[1, 0, 0]], [[0, 1]]], "C_1 has the wrong number of columns; expected 2, got 3"),
        (np.eye(2), [[[1, 0]]], "N >= 2 channels"),
        (np.eye(2), [[[1, 0]], [[0, 0]]], "channel 2 .* observes no direction"),
    ],
)
def test_bad_systems_raise_own_error(A, C, match):
    with pytest.raises(InvalidSystem, match=match):
        LTISystem(A, None, C)


def test_B_shape_checked():
    with pytest.raises(InvalidSystem, match="B has the wrong number of rows; expected 2, got 3"):
        LTISystem(np.eye(2), np.ones((3, 1)), [[[1, 0]], [[0, 1]]])


def test_yaml_round_trip_and_schema_errors(tmp_path, paper):
    import yaml

    p = tmp_path / "sys.yaml"
    p.write_text(yaml.safe_dump(paper.to_dict()))
    s = load_system(p)
    assert s.fingerprint() == paper.fingerprint()
    assert s.state_labels == paper.state_labels and s.channel_names == paper.channel_names

    (tmp_path / "scen.yaml").write_text("scenario: camera_agents\nagents: 3\n")
    assert load_system(tmp_path / "scen.yaml").N == 3

    bad = tmp_path / "bad.yaml"
    bad.write_text("A: [[0, 1], [0, 0]]\n")
    with pytest.raises(InvalidSystem, match="missing required key 'channels'"):
        load_system(bad)
    bad.write_text("A: [[0, 1], [0, 0]]\nchannels: [{C: [[1, 0]]}, {C: [[0, 1]]}]\ncolor: red\n")
    with pytest.raises(InvalidSystem, match=r"unknown key\(s\) \['color'\]"):
        load_system(bad)
    bad.write_text("A: [[0, 1], [0, 0]\n")
    with pytest.raises(InvalidSystem, match="not valid YAML"):
        load_system(bad)
    with pytest.raises(InvalidSystem, match="unknown scenario 'nope'"):
        load_system("nope")
    with pytest.raises(InvalidSystem, match="does not exist"):
        load_system(tmp_path / "missing.yaml")


def test_fingerprint_changes_with_any_matrix(paper):
    A = np.array(paper.A)
    A[7, 7] = 0.2000001
    other = LTISystem(A, None, paper.C)
    assert other.fingerprint() != paper.fingerprint()
    assert LTISystem(paper.A, None, paper.C).fingerprint() == paper.fingerprint()


def test_camera_agents_default_agents_all_differ():
    # Every agent has its own unstable mode, so no two channels are alike (M = 10).
    s = camera_agents(10)
    d = [s.A[4 * j + 3, 4 * j + 3] for j in range(1, 11)]
    assert d[:2] == [0.2, 0.1] and len(set(d)) == 10 and min(d) > 0
    assert len({round(c.mu, 12) for c in s.channels()}) == 10


def test_camera_agents_modes_stay_of_the_papers_order():
    """Many agents invent no faster modes: agent j >= 2 has 0.05 + 0.05 / (j - 1) (agent 2 the paper's
    0.1), all in (0.05, 0.1] beside agent 1's 0.2, and adding agents changes none of the others."""
    s8, s32 = camera_agents(8), camera_agents(32)
    d32 = [s32.A[4 * j + 3, 4 * j + 3] for j in range(1, 33)]
    assert d32[:2] == [0.2, 0.1] and d32[2] == pytest.approx(0.075) and d32[31] == pytest.approx(0.05 + 0.05 / 31)
    assert all(0.05 < x <= 0.1 for x in d32[1:]) and len(set(d32)) == 32
    assert np.array_equal(s32.A[:36, :36], s8.A)
