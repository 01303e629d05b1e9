"""The estimator recovers its guarantee (switchobs_core.runtime.recovery) through ``switchobs_bag
estimate``: a recording with a 5 cm bias on the target poses, and one started with ``e0: -1`` and
an initial estimate metres off. No published bound is ever below the error; the bounds come back,
and the typed ErrorBounds say since when they were re-certified."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from switchobs_msgs.msg import ErrorBounds

from msg_bridge.typed import read_error_bounds
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.io import BagIn
from switchobs_ros.bag.report import load_report
from switchobs_ros.config import EstimatorConfig
from switchobs_ros.core_config import DEFAULT_X0
from switchobs_ros.params import ConfigError

PARAMS = {"gain_family": "kalman", "rate": 50.0, "noise.measurement_std": 0.01, "noise.process_std": 0.01,
          "noise.max": 0.03}
OFF = np.array([3, -2, 0.5, 0.5, 2, 2, 0, 0, -3, 1, 0.3, 0], float)


@pytest.fixture(scope="module")
def bias_bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("recovery")
    generate(d / "bias", GenerateConfig(rate=50.0, duration=12.0, noise_std=0.01, noise_max=0.03, extended=True,
                                        bias=(4.5, 6.5, 0.05)), "mcap")
    return d


def _run(d, name, **over):
    params = {**PARAMS, "gain_table_cache_dir": str(d / "cache"), **over}
    res = estimate(d / "bias", estimator_params(overrides=params), out=d / name)
    (p,) = load_report(d / name, "/estimator").passes
    return res, p


def test_a_bias_on_the_target_poses_withdraws_and_the_bounds_come_back(bias_bag):
    res, p = _run(bias_bag, "bias-est", e0=10.0)
    valid = p.noise > 0
    assert not np.any(valid & (p.err > p.noise))            # no false sample
    assert res.bias_alarms >= 1 and res.recertifications >= 1 and res.bound_valid
    assert not valid[(p.t >= 4.5) & (p.t < 4.6)].all()      # withdrawn within a few samples of the bias
    assert valid[p.t >= 6.5 + 4.0].mean() >= 0.9            # and valid again two cycles after it
    assert "re-certified from data at stamp" in res.recertified
    with BagIn(bias_bag / "bias-est") as bag:
        eb = [read_error_bounds(deserialize_message(m.data, ErrorBounds))
              for m in bag.messages(["/estimator/error_bounds"])]
    last = eb[-1]
    assert last.noise_bound_valid and last.why_invalid.startswith("re-certified from data at stamp")
    assert any(not r.noise_bound_valid and "persistent bias" in r.why_invalid for r in eb)


def test_without_e0_no_bound_until_the_data_certify_one(bias_bag):
    x0 = list(np.array(DEFAULT_X0) + OFF)
    res, p = _run(bias_bag, "e0-est", e0=-1.0, initial_estimate=x0)
    valid = p.noise > 0
    assert not np.any(valid & (p.err > p.noise))
    assert not valid[p.t < 2.0].any() and valid[(p.t >= 2.1) & (p.t < 4.5)].all()     # one cycle of data
    assert res.recertifications >= 1


def test_e0_minus_one_is_the_only_negative_value_accepted():
    assert EstimatorConfig.from_values({"e0": -1.0}).e0 is None
    assert EstimatorConfig.from_values({"e0": 2.5}).e0 == 2.5
    with pytest.raises(ConfigError, match="e0"):
        EstimatorConfig.from_values({"e0": -2.0})


@pytest.mark.parametrize("reinit", [True, False])
def test_a_body_the_gate_starves_is_reinitialised_not_coasted(tmp_path, reinit):
    """Gaussian noise, no declared bound, the chi-square gate on: agent 1 starts accelerating at
    4 m/s^2 (its target poses, from 6 s on). The gate rejects its samples in a row: a model failure,
    said so, and (``consistency.reinit``) agent 1 re-initialised from its samples instead of coasted."""
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import UInt8

    from switchobs_ros.bag.io import deserialize
    from switchobs_ros.pipeline import EstimatorPipeline

    generate(tmp_path / "g", GenerateConfig(rate=50.0, duration=9.0, noise_std=0.01, seed=4), "mcap")
    over = {**PARAMS, "noise.max": -1.0, "gain_table_cache_dir": str(tmp_path / "cache"),
            "consistency.chi2_alpha": 0.01, "consistency.reinit": reinit, "e0": 10.0}
    pl = EstimatorPipeline.from_params(estimator_params(overrides=over))
    channel, last_x, est = 0, None, None
    with BagIn(tmp_path / "g") as b:
        msgs = b.messages(["/camera/active_channel", "/camera/pose", "/target/pose"])
    for m in msgs:
        msg = deserialize(m, UInt8 if m.topic.endswith("channel") else PoseStamped)
        t = (m.log_ns - msgs[0].log_ns) * 1e-9
        if m.topic.endswith("channel"):
            channel = msg.data
        elif m.topic == "/target/pose" and channel == 1 and t >= 6.0:
            msg.pose.position.x += 2.0 * (t - 6.0) ** 2
            last_x = msg.pose.position.x
        for e in pl.on_message(m.topic[1:], msg, m.log_ns):
            if e.channel == 1:
                est = e.x_hat[4]        # agent1.p_x
    assert pl.model_failures >= 1 and "model failure" in pl.last_alarm
    if reinit:
        assert abs(est - last_x) < 0.1      # re-initialised from its own samples (measured: 3 mm)
    else:
        assert abs(est - last_x) > 5.0      # coasting on the model it left (measured: 17.7 m)


def test_a_noise_free_declaration_certifies_a_bound_from_exact_data(tmp_path):
    """A noise-free recording (the extended-precision plant, no noise), ``noise.max: 0`` and
    ``e0: -1`` with an initial estimate metres off: no bound for the first cycle, then one certified
    from the data at the rounding level that holds on every later sample."""
    generate(tmp_path / "exact", GenerateConfig(rate=50.0, duration=5.0, noise_std=0.0, extended=True), "mcap")
    x0 = list(np.array(DEFAULT_X0) + OFF)
    params = {**PARAMS, "noise.max": 0.0, "e0": -1.0, "initial_estimate": x0,
              "gain_table_cache_dir": str(tmp_path / "cache")}
    res = estimate(tmp_path / "exact", estimator_params(overrides=params), out=tmp_path / "est")
    (p,) = load_report(tmp_path / "est", "/estimator").passes
    valid = p.noise > 0
    assert not np.any(valid & (p.err > p.noise))
    assert not valid[p.t < 2.0].any() and valid[p.t >= 2.1].all()
    assert res.recertifications == 1 and np.max(p.noise[p.t >= 2.1]) < 1e-3
