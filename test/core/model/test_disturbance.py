"""Tests of switchobs_core.model.disturbance: the declaration, its defaults and the Kalman Q."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.exceptions import InvalidSystem
from switchobs_core.model.disturbance import Disturbance, velocity_inputs
from switchobs_core.model.scenarios import load_disturbance, load_noise, load_system


def test_built_in_scenarios_have_unit_accelerations_and_no_bound(paper):
    B = velocity_inputs(paper)
    vel = [i for i, lab in enumerate(paper.state_labels) if ".v_" in lab]
    assert B.shape == (12, 6) and np.array_equal(B, np.eye(12)[:, vel])
    d = load_disturbance("paper", paper)
    assert np.array_equal(d.B_w, B) and not d.active
    d2 = load_disturbance("paper", paper, w_max=0.2)
    assert d2.active and np.array_equal(d2.w_max, np.full(6, 0.2))
    d3 = load_disturbance("paper", paper, w_max=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    assert d3.w_max.tolist() == [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    assert load_disturbance("paper", paper, w_max=()).w_max.tolist() == [0.0] * 6


def test_a_yaml_declaration_and_its_errors(tmp_path):
    f = tmp_path / "cart.yaml"
    f.write_text("A: [[0, 1], [0, 0]]\nchannels:\n  - C: [[1, 0]]\n  - C: [[1, 0]]\n"
                 "disturbance:\n  B_w: [[0], [1]]\n  max: 0.5\n")
    s = load_system(str(f))
    d = load_disturbance(str(f), s)
    assert d.B_w.tolist() == [[0.0], [1.0]] and d.w_max.tolist() == [0.5]
    np.testing.assert_array_equal(d.intensity(), [[0.0, 0.0], [0.0, 0.25]])
    assert load_disturbance(str(f), s, w_max=2.0).w_max.tolist() == [2.0]
    for bad in ([1.0, 2.0], -1.0, float("nan"), "x"):
        with pytest.raises(InvalidSystem, match="disturbance"):
            load_disturbance(str(f), s, w_max=bad)
    with pytest.raises(InvalidSystem, match="unknown key"):
        Disturbance.from_mapping({"B": 1}, s)
    with pytest.raises(InvalidSystem, match="n = 2 rows"):
        Disturbance.from_mapping({"B_w": [[1, 0, 0]], "max": 1}, s)
    plain = tmp_path / "plain.yaml"
    plain.write_text("A: [[0, 1], [0, 0]]\nchannels:\n  - C: [[1, 0]]\n  - C: [[1, 0]]\n")
    with pytest.raises(InvalidSystem, match="declares no disturbance input"):
        load_disturbance(str(plain), load_system(str(plain)), w_max=0.1)


def test_the_kalman_process_noise_follows_b_w(paper):
    """``Q_c = B_w diag(max^2) B_w'`` when no process noise is given; an explicit one wins."""
    d = load_disturbance("paper", paper, w_max=0.2)
    Q = load_noise("paper", paper, disturbance=d).Q_c
    vel = [i for i, lab in enumerate(paper.state_labels) if ".v_" in lab]
    expected = np.zeros((12, 12))
    expected[vel, vel] = 0.04
    np.testing.assert_allclose(Q, expected, rtol=1e-15, atol=0)
    np.testing.assert_allclose(load_noise("paper", paper, process_q=0.1, disturbance=d).Q_c, 0.01 * np.eye(12))
    np.testing.assert_allclose(load_noise("paper", paper, disturbance=load_disturbance("paper", paper)).Q_c,
                               1e-4 * np.eye(12))
