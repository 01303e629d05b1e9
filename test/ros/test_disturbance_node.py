"""Bodies that manoeuvre, through the node: camera_sim drives every velocity with a bang-bang
acceleration of 0.2 m/s^2, the estimator declares disturbance.max 0.2 (and the shipped noise-free
noise.max 0), both over DDS; every published guaranteed bound (noise_bound) holds, and it is
published on the samples after the first two cycles (no withdrawal)."""

from __future__ import annotations

import numpy as np
import pytest

from tools import demo


@pytest.mark.slow
def test_a_declared_disturbance_keeps_the_node_bound_true_on_manoeuvring_bodies(paper_tables):
    res = demo.run("periodic", duration=10.0, time_scale=1.0, rate=50.0, init="paper",
                   gain_table=paper_tables["periodic"], out=None, quiet=True,
                   extra_camera={"accel_max": 0.2, "seed": 3},
                   extra_estimator={"noise.max": 0.0, "disturbance.max": [0.2]})
    t, err, bound = res["t"], res["err"], res["exact"]        # the last envelope entry: noise_bound here
    assert res["n_state"] >= 0.99 * res["n_truth"] and t[-1] >= 9.0
    valid = bound > 0
    assert np.all(err[valid] <= bound[valid] * (1 + 1e-9)), float(np.max(err[valid] / bound[valid]))
    late = t >= 4.0                                           # after the first two cycles
    assert np.mean(valid[late]) >= 0.95, np.mean(valid[late])
    assert float(np.max(err)) > 1e-3                          # the bodies did manoeuvre: the estimate lags
