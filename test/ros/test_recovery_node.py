"""The guarantee recovered from data, through the node over DDS: the estimator started with
``e0: -1`` (the initial error unknown) publishes no bound until one switching cycle of data
certifies one, then a valid bound on the samples after three cycles; no published estimate is
ever above a valid bound (camera_sim's noise, 1 mm, within the declared noise.max of 6 mm)."""

from __future__ import annotations

import numpy as np
import pytest

from tools import demo


@pytest.mark.slow
def test_unknown_e0_over_dds_a_bound_certified_from_data(paper_tables):
    res = demo.run("periodic", duration=8.0, time_scale=1.0, rate=50.0, init="zeros",
                   gain_table=paper_tables["periodic"], out=None, quiet=True, noise_std=0.001,
                   extra_camera={"seed": 4}, extra_estimator={"e0": -1.0, "noise.max": 0.006})
    t, err, bound = res["t"], res["err"], res["exact"]        # the last envelope entry: noise_bound
    assert res["n_state"] >= 0.99 * res["n_truth"] and t[-1] >= 7.0
    valid = bound > 0
    assert np.all(err[valid] <= bound[valid] * (1 + 1e-9)), float(np.max(err[valid] / bound[valid]))
    assert not valid[t < 1.9].any()                           # nothing before a full cycle of data
    assert 1.9 <= t[valid][0] <= 2.5, t[valid][0]             # then certified from the window
    assert np.mean(valid[t >= 6.0]) >= 0.9
    assert err[0] > 1.0                                       # it did start metres off
