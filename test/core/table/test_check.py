"""Re-verification of loaded gain tables (switchobs_core.table.check): a table whose
gains were zeroed and whose checksum was recomputed loads (the checksum is not a signature) but is
refused before use; real tables of every family pass, cheaply; the Kalman check's period map is the
dense product, and bit for bit the product through scipy's public sparse product."""

from __future__ import annotations

import json
import time
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.sparse import csr_array

from switchobs_core.design.kalman import design_kalman
from switchobs_core.exceptions import GainTableError
from switchobs_core.model.scenarios import camera_agents
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import LTISystem
from switchobs_core.table import check
from switchobs_core.table.check import _apply_phase, _period_map, _selected, _transition, verify_table
from switchobs_core.table.gains import GainTable, kalman_table
from switchobs_core.table.kalman import KalmanDesign


def _replant(table: GainTable, edit) -> GainTable:
    """``table`` through its file text with ``edit(data)`` applied and the checksum recomputed."""
    data = json.loads(table.to_json())
    data.pop("payload_sha256")
    edit(data)
    data["payload_sha256"] = GainTable._digest(data)
    return GainTable.from_json(json.dumps(data), source="planted.json")


def _zero_lmi(data):
    for d in data["designs"]:
        for ch in d["channels"]:
            ch["L"] = [[0.0] * len(r) for r in ch["L"]]
            ch["L_o"] = [[0.0] * len(r) for r in ch["L_o"]]


def _zero_kalman(data):
    for k in data["kalman"]:
        for part in ("periodic", "startup"):
            k[part]["K"] = [[[0.0] * len(r) for r in K] for K in k[part]["K"]]


@pytest.fixture(scope="module")
def kalman(paper):
    return kalman_table(paper, [design_kalman(paper, [Cycle.from_ts(2.0, 0.6)], 20.0)])


def test_real_tables_pass_quickly(paper, paper_table, paper_designer, kalman):
    robust = paper_designer.table([], robust=(0.8, 1.6), progress=False)
    t0 = time.monotonic()
    for t in (paper_table, robust, kalman):
        verify_table(t, paper)
    assert time.monotonic() - t0 < 2


def test_zeroed_lmi_gains_with_a_recomputed_checksum_are_refused(paper, paper_table):
    planted = _replant(paper_table, _zero_lmi)         # loads: the checksum matches
    with pytest.raises(GainTableError, match=r"planted.json: design \(2 s, 0.6\): the error map over the cycle "
                                             r"\(2 s, 0.6\) has spectral radius 1.49\d* >= 1"):
        verify_table(planted, paper, source="planted.json")


def test_zeroed_kalman_gains_are_refused(paper, kalman):
    planted = _replant(kalman, _zero_kalman)
    with pytest.raises(GainTableError, match=r"Kalman design at 20 Hz: the error map over one period has spectral "
                                             r"radius .* >= 1"):
        verify_table(planted, paper, source="planted.json")


def test_the_check_and_the_observer_read_one_design_built_once(paper, kalman):
    """The design the check verifies is the one :meth:`GainTable.kalman_design` gives the observer (one
    build of the stored phases), the same numbers as a build of its own; a zeroed table is refused
    through the same path, and its design is not the one of the table it was planted from."""
    table = GainTable.from_json(kalman.to_json(), source="k.json")
    verify_table(table, paper)
    kd = table.kalman_design([Cycle.from_ts(2.0, 0.6)], paper)
    assert kd is table.stored_kalman(table.kalman[0], paper)
    fresh = KalmanDesign.from_dict(table.kalman[0], paper)
    for a, b in zip(kd.startup + kd.periodic, fresh.startup + fresh.periodic, strict=True):
        assert a.channel == b.channel and a.dt == b.dt and np.array_equal(a.K, b.K)
    assert np.array_equal(_period_map(kd, paper, "x"), _period_map(fresh, paper, "x"))

    planted = _replant(table, _zero_kalman)
    with pytest.raises(GainTableError, match="spectral radius"):
        verify_table(planted, paper, source="planted.json")
    assert not np.array_equal(planted.stored_kalman(planted.kalman[0], paper).periodic[0].K, kd.periodic[0].K)


def test_gain_of_the_wrong_shape_or_not_finite_is_refused(paper, paper_table):
    """(A file with either is refused by the loader's layout check already; a table built in memory
    is checked here.)"""
    d = paper_table.designs[0]
    for L, needle in ((np.zeros((12, 3)), r"gain L_1 has shape \(12, 3\); expected \(12, 4\)"),
                      (np.full((12, 4), np.nan), "gain L_1 has a non-finite entry")):
        bad = replace(d, channels=(replace(d.channels[0], L=L),) + d.channels[1:])
        with pytest.raises(GainTableError, match=needle):
            verify_table(replace(paper_table, designs=[bad]), paper)


@pytest.fixture(scope="module")
def agents():
    """Three decoupled bodies (n = 12): a sparse sample transition."""
    return camera_agents(2)


def test_period_map_equals_the_dense_product(agents):
    """The check's period map (rank-p corrections, the transition sparse) is the product
    ``prod (I - K H) Phi`` formed densely, to 1e-12 relative; its transition was taken sparse."""
    table = kalman_table(agents, [design_kalman(agents, Cycle([0.5, 0.5]), 20.0)])
    kd = KalmanDesign.from_dict(table.kalman[0], agents)
    n = agents.n
    A = np.asarray(agents.A)
    assert not isinstance(_transition(expm(A * 0.05)), np.ndarray)
    ref = np.eye(n)
    for ph in kd.periodic:
        C = np.asarray(agents.C[ph.channel - 1])
        H = C if ph.rows is None else C[list(ph.rows)]
        ref = (np.eye(n) - np.asarray(ph.K) @ H) @ expm(A * ph.dt) @ ref
    got = _period_map(kd, agents, "t")
    assert np.max(np.abs(got - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref)))
    verify_table(table, agents)

    with pytest.raises(GainTableError, match="spectral radius"):
        verify_table(_replant(table, _zero_kalman), agents, source="planted.json")


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), dt=st.sampled_from([0.01, 0.05, 0.5]), cols=st.integers(1, 12),
       select=st.booleans())
def test_sparse_transition_applied_as_scipys_product(agents, seed, dt, cols, select):
    """A phase ``(I - K H) Phi M`` with a sparse transition (scipy's kernel called directly,
    :func:`_apply_phase`) gives the bytes of ``csr_array @ dense`` followed by the correction, for dense
    factors of any values and widths, with a general ``H`` or one that selects states; a dense transition
    is a plain product."""
    rng = np.random.default_rng(seed)
    n = agents.n
    Phi = _transition(expm(np.asarray(agents.A) * dt))
    assert isinstance(Phi, csr_array)
    M = rng.standard_normal((n, cols)) * 10.0 ** rng.integers(-8, 8)
    p = int(rng.integers(1, 5))
    H = np.eye(n)[rng.choice(n, p, replace=False)] if select else rng.standard_normal((p, n))
    picked = _selected(H)
    assert (picked is not None) == select
    K = rng.standard_normal((n, p))
    for T in (Phi, Phi.toarray()):
        PM = np.asarray(T @ M)
        ref = PM - K @ (H @ PM)
        got, _ = _apply_phase(T, K, H, picked, M.copy(), np.empty((n, cols)))
        assert got.tobytes() == ref.tobytes()


def test_period_map_is_the_public_products_bit_for_bit(agents):
    """The period map (each phase's rows made once, the sparse kernel called directly, the correction
    subtracted in place) is, byte for byte, the loop written with scipy's public ``csr_array @ dense``
    and a new array per phase."""
    table = kalman_table(agents, [design_kalman(agents, Cycle([0.5, 0.5]), 20.0)])
    kd = KalmanDesign.from_dict(table.kalman[0], agents)
    A = np.asarray(agents.A)
    M = np.eye(agents.n)
    for ph in kd.periodic:
        C = np.asarray(agents.C[ph.channel - 1], dtype=float)
        H = C if ph.rows is None else C[list(ph.rows)]
        PM = _transition(expm(A * ph.dt)) @ M
        M = PM - np.asarray(ph.K, dtype=float) @ (H @ PM)
    assert _period_map(kd, agents, "t").tobytes() == M.tobytes()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 4), kind=st.sampled_from(["pick", "weight", "two", "zero"]))
def test_a_selecting_output_is_its_rows_bit_for_bit(seed, rows, kind):
    """An ``H`` whose rows each read one state with weight 1 is applied as those rows of the map: the
    bytes of ``H @ M`` for finite maps of any magnitudes; any other ``H`` (another weight, two states
    in a row, a row of zeros) is not taken for a selection."""
    rng = np.random.default_rng(seed)
    n = 9
    H = np.zeros((rows, n))
    H[np.arange(rows), rng.choice(n, size=rows)] = 1.0
    if kind == "weight":
        H[rng.integers(rows), :] *= 2.0
    elif kind == "two":
        r = rng.integers(rows)
        H[r, (np.argmax(H[r]) + 1) % n] = 0.5
    elif kind == "zero":
        H[rng.integers(rows)] = 0.0
    picked = _selected(H)
    if kind != "pick":
        assert picked is None
        return
    M = rng.standard_normal((n, n)) * 10.0 ** rng.integers(-300, 300, size=(n, 1))
    assert M[picked].tobytes() == (H @ M).tobytes()


def test_period_map_with_weighted_outputs_is_the_public_products(agents):
    """Outputs that are not selections (each channel's rows scaled by 2 and mixed): the period map is still
    the public loop's bytes."""
    mix = np.eye(4) * 2.0
    mix[0, 1] = 0.5
    system = LTISystem(agents.A, None, [mix @ np.asarray(C) for C in agents.C])
    table = kalman_table(system, [design_kalman(system, Cycle([0.5, 0.5]), 20.0)])
    kd = KalmanDesign.from_dict(table.kalman[0], system)
    A = np.asarray(system.A)
    M = np.eye(system.n)
    for ph in kd.periodic:
        C = np.asarray(system.C[ph.channel - 1], dtype=float)
        H = C if ph.rows is None else C[list(ph.rows)]
        assert _selected(H) is None
        PM = _transition(expm(A * ph.dt)) @ M
        M = PM - np.asarray(ph.K, dtype=float) @ (H @ PM)
    assert _period_map(kd, system, "t").tobytes() == M.tobytes()
    verify_table(table, system)


def test_a_non_finite_kalman_gain_is_refused_naming_its_sample(agents):
    """One NaN in the gain of one stored sample (the gains read as views of one array): refused in one
    line naming that sample, not as a spectral radius."""
    table = kalman_table(agents, [design_kalman(agents, Cycle([0.5, 0.5]), 20.0)])
    kd = KalmanDesign.from_dict(table.kalman[0], agents)
    K = np.array(kd.periodic[3].K, dtype=float)
    K[2, 1] = np.nan
    bad = replace(kd, periodic=[*kd.periodic[:3], replace(kd.periodic[3], K=K), *kd.periodic[4:]])
    with pytest.raises(GainTableError, match=r"^t: Kalman design 20 Hz, gain of sample 3 has a non-finite entry$"):
        _period_map(bad, agents, "t")
    stacked = np.stack([np.asarray(ph.K, dtype=float) for ph in kd.periodic])
    stacked[5, 0, 0] = np.inf
    views = replace(kd, periodic=[replace(ph, K=stacked[i]) for i, ph in enumerate(kd.periodic)])
    with pytest.raises(GainTableError, match=r"gain of sample 5 has a non-finite entry$"):
        _period_map(views, agents, "t")


def test_runs_over_a_few_decoupled_blocks_give_the_dense_product(monkeypatch):
    """Four agents (n = 20): each residence's gains and output touch the camera's and one agent's
    blocks (8 states), so the residence is applied at once (the small product on those states, the
    transition's power on the others): the dense product ``prod (I - K H) Phi`` to 1e-12 relative, every
    run taken that way; zeroed gains are still refused."""
    system = camera_agents(4)
    table = kalman_table(system, [design_kalman(system, Cycle([0.5] * 4), 20.0)])
    kd = KalmanDesign.from_dict(table.kalman[0], system)
    n = system.n
    A = np.asarray(system.A)
    ref = np.eye(n)
    for ph in kd.periodic:
        C = np.asarray(system.C[ph.channel - 1])
        H = C if ph.rows is None else C[list(ph.rows)]
        ref = (np.eye(n) - np.asarray(ph.K) @ H) @ expm(A * ph.dt) @ ref
    runs, states = [], []
    real_run, real_states = check._apply_run, check._run_states
    monkeypatch.setattr(check, "_apply_run", lambda *a: runs.append(len(a[4])) or real_run(*a))
    monkeypatch.setattr(check, "_run_states", lambda *a: states.append(real_states(*a)) or states[-1])
    got = _period_map(kd, system, "t")
    assert np.max(np.abs(got - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref)))
    assert sum(runs) == len(kd.periodic) and len(runs) == 4
    assert all(S is not None and S.size == 8 and set(S[:4]) == {0, 1, 2, 3} for S in states)
    monkeypatch.undo()
    verify_table(table, system)

    with pytest.raises(GainTableError, match="spectral radius"):
        verify_table(_replant(table, _zero_kalman), system, source="planted.json")


def test_blocks_of_a_transition_are_its_coupled_states():
    """The blocks of a sparse transition are the connected states (a coupling either way joins two)."""
    Phi = np.eye(6)
    Phi[0, 3] = 0.5          # 0 and 3 coupled one way
    Phi[4, 1] = -2.0         # 1 and 4 the other way
    Phi[4, 5] = 1e-300       # 5 joins them through 4
    label = check._blocks(csr_array(Phi))
    groups = {frozenset(np.flatnonzero(label == b).tolist()) for b in set(label.tolist())}
    assert groups == {frozenset({0, 3}), frozenset({1, 4, 5}), frozenset({2})}
