"""Refactors change no number: the offline estimator (the node's pipeline) on stored bags
reproduces what the code before the consolidation of configuration, cycle bookkeeping and the
paper's factor (commit 5a18045) recorded: the estimates bit for bit, the paper's envelopes bit for
bit, and the exact bound up to its new allowance for rounding; for the periodic, sequence and
random (robust) schedules, with measurement and process noise, from mcap and sqlite3 bags and the
gain tables (format version 1) that code wrote. The data: test/ros/data/regression (cases.json
says how each bag and estimate were made)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from switchobs_ros.bag.estimate import estimate, estimator_params

DATA = Path(__file__).resolve().parent / "data" / "regression"
CASES = json.loads((DATA / "cases.json").read_text())


@pytest.mark.parametrize("name", sorted(CASES))
def test_estimates_bit_identical_to_recorded(name):
    params = dict(CASES[name]["params"])
    params["gain_table"] = str(DATA / params["gain_table"])
    params["e0"] = 5.0
    got = estimate(DATA / name, estimator_params(overrides=params))
    want = np.load(DATA / f"{name}.npz")
    assert got.stamps.size == want["stamps"].size > 100
    assert np.array_equal(got.stamps, want["stamps"])
    assert np.array_equal(got.x_hat, want["x_hat"]), np.abs(got.x_hat - want["x_hat"]).max()
    # the paper's envelopes z_i and bound: bit-identical
    assert np.array_equal(got.envelope[:, :-1], want["envelope"][:, :-1])
    # the exact bound now includes floating-point rounding (switchobs_core.rounding): never below
    # the recorded exact-arithmetic ||Phi|| e0, and above it only by the rounding allowance
    ratio = got.envelope[:, -1] / want["envelope"][:, -1]
    assert ratio.min() >= 1.0 and ratio.max() < 1.0 + 1e-5, (ratio.min(), ratio.max())
