"""A biased sensor through the node over DDS: camera_sim adds 5 cm to the target poses for 2 s
(``bias.*``; camera_sim's noise 1 mm, the estimator's Kalman gains for it and a declared noise.max
of 6 mm); the estimator withdraws its bounds at the fault, no published estimate is ever above a
valid bound, and a valid bound is back on at least 90 % of the samples from two switching cycles
after the fault."""

from __future__ import annotations

import numpy as np
import pytest

from tools import demo

T0, T1, CYCLE = 5.0, 7.0, 2.0


@pytest.mark.slow
def test_a_bias_over_dds_withdraws_the_bounds_and_they_come_back(tmp_path):
    res = demo.run("periodic", duration=15.0, time_scale=1.0, rate=50.0, init="paper", out=None, quiet=True,
                   noise_std=0.001,
                   extra_camera={"seed": 5, "bias.offset_m": 0.05, "bias.start_s": T0, "bias.duration_s": T1 - T0},
                   extra_estimator={"noise.max": 0.006, "gain_family": "kalman", "noise.measurement_std": 0.001,
                                    "rate": 50.0, "gain_table_cache_dir": str(tmp_path)})
    t, err, bound = res["t"], res["err"], res["exact"]        # the last envelope entry: noise_bound
    assert res["n_state"] >= 0.99 * res["n_truth"] and t[-1] >= 14.0
    valid = bound > 0
    assert np.all(err[valid] <= bound[valid] * (1 + 1e-9)), float(np.max(err[valid] / bound[valid]))
    assert valid[t < T0].all()                                # the model held before the fault
    assert not valid[(t >= T0 + 0.2) & (t < T1)].any()       # withdrawn while the sensor is biased
    late = t >= T1 + 2 * CYCLE
    assert np.mean(valid[late]) >= 0.9, np.mean(valid[late])


def test_the_bias_parameters_are_checked_and_bias_only_the_target_poses():
    from switchobs_core.model.scenarios import load_system
    from switchobs_ros.camera_sim import _bias
    from switchobs_ros.params import ConfigError

    paper = load_system("paper")
    cfg = {"bias.offset_m": 0.05, "bias.start_s": T0, "bias.duration_s": 2.0, "bias.channel": 2}
    b = _bias(cfg, paper)
    y = np.arange(4.0)
    assert np.array_equal(b.add(T0, 2, y), y + [0, 0, 0.05, 0.05])      # the camera's own pose untouched
    assert b.add(T0, 1, y) is y and b.add(T1, 2, y) is y and b.add(T0 - 1e-9, 2, y) is y
    assert _bias({**cfg, "bias.offset_m": 0.0}, paper) is None
    for bad in ({"bias.duration_s": 0.0}, {"bias.start_s": -1.0}, {"bias.channel": 3}, {"bias.offset_m": float("nan")},
                {"bias.duration_s": float("inf")}):
        with pytest.raises(ConfigError, match=next(iter(bad)).replace(".", r"\.")):
            _bias({**cfg, **bad}, paper)
