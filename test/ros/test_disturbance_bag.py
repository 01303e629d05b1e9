"""A recording of manoeuvring bodies through `switchobs_bag estimate`: with the accelerations
within the declared `disturbance.max` and the noise within `noise.max`, no published sample is
above a valid `noise_bound` and every bound stays valid (the undeclared case:
test/core/sim/test_disturbed.py)."""

from __future__ import annotations

import numpy as np

from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.report import load_report
from switchobs_ros.core_config import DEFAULT_X0


def _estimate(tmp_path, paper_tables, name, **over):
    """The recording in ``tmp_path / "in"`` through the bag estimator; (result, the report's pass)."""
    e0 = float(np.linalg.norm(DEFAULT_X0)) * 1.01        # the estimate starts at 0
    params = {"gain_table": paper_tables["periodic"], "e0": e0, "noise.max": 3e-3,
              "output.odometry_every": 0, "output.typed_every": 0, **over}
    res = estimate(tmp_path / "in", estimator_params(overrides=params), out=tmp_path / name)
    (p,) = load_report(tmp_path / name, "/estimator").passes
    return res, p


def test_accelerations_within_the_declared_disturbance_keep_a_valid_true_bound(tmp_path, paper_tables):
    generate(tmp_path / "in", GenerateConfig(rate=50.0, duration=6.0, extended=True, noise_std=1e-3,
                                             noise_max=3e-3, accel_max=0.2, seed=3), "mcap")
    res, p = _estimate(tmp_path, paper_tables, "declared", **{"disturbance.max": 0.2})
    assert res.inconsistent == 0 and res.bound_valid
    assert len(p.t) == 301 and np.all(p.noise >= 0) and p.violations(p.noise) == 0
