"""A known input held between samples: SwitchedObserver.hold_input changes the held ``u`` at its own
time (a command's stamp), exactly as the plant's zero-order hold, and leaves the error, Phi and the
bounds as they are without an input (``B u`` cancels in the error, e:system)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.design.kalman import design_kalman
from switchobs_core.design.lmi import design_table
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.model.system import LTISystem
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.sim.plant import Plant
from switchobs_core.table.gains import kalman_table

CYC = Cycle.from_ts(2.0, 0.6)
RATE = 20.0
X0 = np.array([0.3, -0.2, 0.1, 0.05, 1.0, 0.5, -0.1, 0.2, -0.8, 0.4, 0.0, -0.1])


def _driven(paper) -> LTISystem:
    """The paper's A and C with the camera's accelerations as the input (B = [0; 0; I; 0])."""
    B = np.zeros((paper.n, 2))
    B[2, 0] = B[3, 1] = 1.0
    return LTISystem(paper.A, B, paper.C, name="paper_driven", state_labels=paper.state_labels,
                     output_labels=paper.output_labels)


def _commands(T: float) -> list[tuple[float, np.ndarray]]:
    """Commands at stamps off the sample grid (and one on it), each held until the next."""
    rng = np.random.default_rng(3)
    stamps = sorted(set(np.round(rng.uniform(0.0, T, 25), 4)) | {1.0})
    return [(float(s), rng.uniform(-2.0, 2.0, 2)) for s in stamps]


def _run(system, table, cmds, T, family=None, driven=True):
    """The plant (exact ZOH of the commands) and the observer fed its samples: errors, bounds."""
    plant = Plant(system, X0)
    obs = SwitchedObserver(system, table, cycles=[CYC], e0=float(np.linalg.norm(X0)) * 1.0001, family=family)
    sched = PeriodicSchedule(CYC)
    u = np.zeros(2)
    k_cmd = 0
    errs, bounds = [], []
    for k in range(int(T * RATE) + 1):
        t = k / RATE
        while k_cmd < len(cmds) and cmds[k_cmd][0] < t:     # commands strictly before the sample
            s, v = cmds[k_cmd]
            plant.advance(s, u if driven else None)
            u = v
            if driven:
                obs.hold_input(s, u)
            k_cmd += 1
        x = plant.advance(t, u if driven else None)
        ch = sched.channel_at(t)
        xh = obs.update(t, ch, system.C[ch - 1] @ x)
        errs.append(x - xh)
        bounds.append(obs.envelope().exact_bound)
    return np.array(errs), np.array(bounds), obs


@pytest.fixture(scope="module")
def driven(paper):
    return _driven(paper)


def test_lmi_error_and_bound_are_those_without_input(driven):
    table = design_table(driven, cycles=[CYC], etas=[(1.6, 3.5)], progress=False)
    T = 4.0
    cmds = _commands(T)
    e_u, b_u, obs = _run(driven, table, cmds, T)
    e_0, b_0, _ = _run(driven, table, cmds, T, driven=False)
    scale = np.abs(e_0).max()
    # the error does not see the input: the same to rounding (the driven run's steps are split at
    # the commands' stamps)
    assert np.abs(e_u - e_0).max() <= 1e-9 * scale
    norms = np.linalg.norm(e_u, axis=1)
    assert int((norms > b_u).sum()) == 0
    np.testing.assert_allclose(b_u, b_0, rtol=1e-9)
    assert obs.t == pytest.approx(T)


def test_kalman_table_stays_locked_across_commands(driven):
    table = kalman_table(driven, [design_kalman(driven, CYC, RATE)])
    T = 4.0
    cmds = _commands(T)
    e_u, b_u, obs = _run(driven, table, cmds, T)
    e_0, _, obs0 = _run(driven, table, cmds, T, driven=False)
    assert obs.kalman_departures == obs0.kalman_departures == 0, obs.kalman_fallback
    assert np.abs(e_u - e_0).max() <= 1e-9 * np.abs(e_0).max()
    assert int((np.linalg.norm(e_u, axis=1) > b_u).sum()) == 0


def test_hold_input_at_a_sample_time_is_update_with_u(driven):
    table = design_table(driven, cycles=[CYC], etas=[(1.6, 3.5)], progress=False)
    a = SwitchedObserver(driven, table, cycles=[CYC], x0=X0)
    b = SwitchedObserver(driven, table, cycles=[CYC], x0=X0)
    y = driven.C[0] @ X0
    u = np.array([1.5, -0.5])
    a.update(0.05, 1, y, u=u)
    b.update(0.05, 1, y)
    b.hold_input(0.05, u)
    np.testing.assert_array_equal(a.x_hat, b.x_hat)
    np.testing.assert_array_equal(a.update(0.1, 1, y), b.update(0.1, 1, y))


def _zoh_input(A, B, u, d):
    """Independent ZOH of a constant input over ``d``: int_0^d e^{A s} ds B u (expm of the augmented matrix)."""
    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = A, B
    return expm(aug * d)[:n, n:] @ u


def test_a_change_between_samples_is_its_exact_zoh_and_checks(driven):
    table = design_table(driven, cycles=[CYC], etas=[(1.6, 3.5)], progress=False)
    obs = SwitchedObserver(driven, table, cycles=[CYC], x0=X0)
    A, B = np.asarray(driven.A), np.asarray(driven.B)
    obs.update(0.05, 1, driven.C[0] @ X0)
    x05 = obs.x_hat
    free = obs.predict(0.1)
    obs.hold_input(0.07, None)          # zero held already: nothing changes
    obs.hold_input(0.07, [0.0, 0.0])
    np.testing.assert_array_equal(obs.predict(0.1), free)
    u1, u2 = np.array([1.0, -2.0]), np.array([0.5, 0.25])
    obs.hold_input(0.07, u1)
    obs.hold_input(0.09, u2)
    assert obs.t == 0.05, "the observer stays at its sample; the next step adds the changes"
    want = expm(A * 0.05) @ x05 + expm(A * 0.01) @ _zoh_input(A, B, u1, 0.02) + _zoh_input(A, B, u2, 0.01)
    np.testing.assert_allclose(obs.predict(0.1), want, rtol=1e-12, atol=1e-13)
    # before the second change only the first acts
    want_08 = expm(A * 0.03) @ x05 + _zoh_input(A, B, u1, 0.01)
    np.testing.assert_allclose(obs.predict(0.08), want_08, rtol=1e-12, atol=1e-13)
    with pytest.raises(InvalidArgument, match="must be a finite time >= the observer's time 0.09"):
        obs.hold_input(0.08, [1.0, 0.0])
    with pytest.raises(InvalidArgument, match="u must hold 2 finite entries"):
        obs.hold_input(0.1, [1.0])
    with pytest.raises(InvalidArgument, match="u must hold 2 finite entries"):
        obs.hold_input(0.1, [np.nan, 0.0])
    # a sample after both: the input held from then on is the last one
    x = obs.update(0.1, 1, driven.C[0] @ X0).copy()
    np.testing.assert_allclose(obs.predict(0.15), expm(A * 0.05) @ x + _zoh_input(A, B, u2, 0.05), rtol=1e-12,
                               atol=1e-13)
