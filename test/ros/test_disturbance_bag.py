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


def test_diagnostics_name_the_declared_disturbance(paper_tables):
    """The node's bound line says under which declarations noise_bound holds."""
    import time as _time

    from std_msgs.msg import UInt8

    import msg_bridge as mb
    from switchobs_ros.config import params_from_file
    from switchobs_ros.diagnostics import EstimatorDiagnostics, NodeState
    from switchobs_ros.pipeline import EstimatorPipeline

    pl = EstimatorPipeline.from_params(params_from_file(overrides={
        "gain_table": paper_tables["periodic"], "reorder_window_ms": 0.0, "e0": 10.0, "noise.max": 3e-3,
        "disturbance.max": 0.2}))
    pl.on_channel(UInt8(data=1))
    s, now = _time.time_ns() - 10**9, _time.time_ns()
    pl.on_pose("camera", mb.xy_to_pose((0.0, 0.0), s, "map"), now)
    pl.on_pose("target", mb.xy_to_pose((3.0, 1.0), s, "map"), now)
    assert pl.updates == 1 and pl.bound_valid
    clock = type("T", (), {"nanoseconds": now, "to_msg": lambda self: mb.ns_to_stamp(now)})()
    arr = EstimatorDiagnostics("/estimator", pl, now).array(clock, NodeState(0, 0, "", 1.0, None, 0))
    keys = [kv.key for st in arr.status for kv in st.values]
    assert "noise bound (|v| <= 0.003 per row, disturbance |w| <= 0.2)" in keys, keys
