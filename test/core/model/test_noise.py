"""The noise model: parsing of the noise: mapping and overrides, validation, persistence."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.exceptions import InvalidArgument, NoiseModelError, SwitchobsError
from switchobs_core.model.noise import (
    DEFAULT_MEAS_STD,
    DEFAULT_P0,
    DEFAULT_PROCESS_STD,
    MAX_ABS_ENTRY,
    NoiseModel,
    default_noise,
)
from switchobs_core.model.scenarios import camera_agents, paper_system

PAPER = paper_system()


def test_default_noise_values():
    m = default_noise(PAPER)
    assert m.p == (4, 4) and m.n == 12
    assert np.array_equal(m.R(2), DEFAULT_MEAS_STD**2 * np.eye(4))
    assert np.array_equal(m.Q_c, DEFAULT_PROCESS_STD**2 * np.eye(12))
    assert np.array_equal(m.P0, DEFAULT_P0 * np.eye(12))


def test_mapping_forms_and_overrides():
    spec = {"measurement_std": [[1e-3, 1e-3, "2e-3", 2e-3], 0.005], "process_intensity": list(range(1, 13)), "P0": 4}
    m = NoiseModel.from_mapping(spec, PAPER)
    assert np.allclose(np.diag(m.R(1)), [1e-6, 1e-6, 4e-6, 4e-6]) and np.allclose(np.diag(m.R(2)), 25e-6)
    assert np.allclose(m.R(1, [2, 3]), np.diag([4e-6, 4e-6]))
    assert np.array_equal(np.diag(m.Q_c), np.arange(1.0, 13.0))
    assert np.array_equal(m.P0, 4 * np.eye(12))
    o = NoiseModel.from_mapping(spec, PAPER, meas_std=0.01, process_q=0.5)
    assert np.allclose(o.R(1), 1e-4 * np.eye(4))
    assert np.allclose(o.Q_c, 0.25 * np.eye(12))  # process_q = q means Qc = q^2 I (the simulator's convention)
    assert NoiseModel.from_mapping(None, PAPER).fingerprint() == default_noise(PAPER).fingerprint()


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"measurement_std": -1e-3}, "measurement_std must be a finite standard deviation > 0"),
        ({"measurement_std": math.nan}, "finite standard deviation"),
        ({"measurement_std": True}, "boolean"),
        ({"measurement_std": [1e-3, 1e-3, 1e-3]}, r"one entry per channel \(N = 2\); got 3"),
        ({"measurement_std": [[1e-3] * 3, 1e-3]}, r"channel 1\] needs p_1 = 4 entries"),
        ({"process_intensity": [1.0] * 11}, "n = 12 entries"),
        ({"process_intensity": -1.0}, "finite number >= 0"),
        ({"process_std": [0.1, 0.2]}, "one number q"),
        ({"process_std": 0.1, "process_intensity": 0.1}, "not both"),
        ({"P0": np.triu(np.ones((12, 12)))}, "must be symmetric"),
        ({"P0": -np.eye(12)}, "positive semidefinite"),
        ({"P0": np.full((12, 12), math.inf)}, "non-finite"),
        ({"P0": np.eye(3)}, r"\(12, 12\) matrix; got shape \(3, 3\)"),
        ({"P0": "big"}, "string 'big'"),
        ({"P0": [[1.0, 2.0], [3.0]]}, "ragged"),
        ({"Q": 1.0}, r"unknown key\(s\) \['Q'\]"),
    ],
)
def test_bad_noise_specs(spec, match):
    with pytest.raises(NoiseModelError, match=match) as err:
        NoiseModel.from_mapping(spec, PAPER)
    assert isinstance(err.value, SwitchobsError) and isinstance(err.value, ValueError)
    assert str(err.value).startswith("noise: ") and "\n" not in str(err.value)


def test_bad_accessors_and_mapping_type():
    m = default_noise(PAPER)
    with pytest.raises(NoiseModelError, match=r"channel must be an integer in 1..2; got 3"):
        m.R(3)
    with pytest.raises(NoiseModelError, match="rows must be 0-based row indices in 0..3"):
        m.R(1, [4])
    with pytest.raises(NoiseModelError, match="must be a mapping"):
        NoiseModel.from_mapping([1e-3], PAPER)
    with pytest.raises(NoiseModelError, match="noise model is for n = 12"):
        m.check_system(camera_agents(3))
    with pytest.raises(NoiseModelError, match="exactly the keys"):
        NoiseModel.from_dict({"meas_std": [[1.0]]})
    with pytest.raises(InvalidArgument, match="Q_c must be a non-empty square matrix"):
        NoiseModel([[1.0]], np.ones((2, 3)), 1.0)


def _std_value():
    return st.floats(min_value=1e-6, max_value=10.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    form=st.sampled_from(["scalar", "channel", "row"]),
    vals=st.lists(_std_value(), min_size=8, max_size=8),
    qdiag=st.lists(st.floats(min_value=0.0, max_value=5.0), min_size=12, max_size=12),
    L=st.lists(st.floats(min_value=-2.0, max_value=2.0), min_size=144, max_size=144),
)
def test_parser_random_valid_models_round_trip(form, vals, qdiag, L):
    """Any valid form expands to the declared per-row std, and to_dict/from_dict is exact."""
    if form == "scalar":
        spec, want = vals[0], [[vals[0]] * 4, [vals[0]] * 4]
    elif form == "channel":
        spec, want = vals[:2], [[vals[0]] * 4, [vals[1]] * 4]
    else:
        spec, want = [vals[:4], vals[4:]], [vals[:4], vals[4:]]
    Lm = np.array(L).reshape(12, 12)
    P0 = Lm @ Lm.T
    m = NoiseModel.from_mapping({"measurement_std": spec, "process_intensity": qdiag, "P0": P0}, PAPER)
    for c in (1, 2):
        assert np.array_equal(np.diag(m.R(c)), np.square(want[c - 1]))
    back = NoiseModel.from_dict(json.loads(json.dumps(m.to_dict())))
    assert back.fingerprint() == m.fingerprint()
    assert np.array_equal(back.P0, m.P0) and np.array_equal(back.Q_c, m.Q_c)


@settings(max_examples=60, deadline=None)
@given(
    shape=st.sampled_from([(), (3,), (11,), (13,), (12, 11), (2, 12, 12)]),
    v=st.floats(allow_nan=True, allow_infinity=True),
)
def test_parser_random_bad_shapes_or_values(shape, v):
    """A wrong shape, or a negative, non-finite or absurdly large value, is refused with a NoiseModelError."""
    arr = np.full(shape, v)
    ok_scalar = shape == () and math.isfinite(v) and 0 <= v <= MAX_ABS_ENTRY
    if ok_scalar:
        assert NoiseModel.from_mapping({"process_intensity": float(v)}, PAPER).Q_c[0, 0] == v
        return
    with pytest.raises(NoiseModelError):
        NoiseModel.from_mapping({"process_intensity": arr}, PAPER)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6), st.data())
def test_matrix_entries_read_at_once_equal_the_element_wise_reading(n, data):
    """A P0 of plain ints and floats is converted in one call (the fast path): the same array as
    entry by entry; one boolean or non-numeric string anywhere is still refused."""
    from switchobs_core.model.noise import _array

    entries = st.one_of(st.integers(-10**6, 10**6), st.floats(-1e6, 1e6, allow_nan=False))
    rows = data.draw(st.lists(st.lists(entries, min_size=n, max_size=n), min_size=n, max_size=n))
    got = _array(rows, "P0")
    assert got.dtype == float and got.shape == (n, n)
    assert np.array_equal(got, np.array([[float(v) for v in r] for r in rows]))
    i, j = data.draw(st.integers(0, n - 1)), data.draw(st.integers(0, n - 1))
    for bad in (True, "ten"):
        rows[i][j] = bad
        with pytest.raises(NoiseModelError):
            _array(rows, "P0")
