"""Acceptance: estimator and camera_sim as separate processes over DDS (sim time, /clock from
camera_sim), the paper's schedules; the published estimate is within 1e-3 of the published
truth, relative to the initial error, after 20 s of simulated time."""

from __future__ import annotations

import numpy as np
import pytest

from tools import demo


@pytest.mark.slow
@pytest.mark.parametrize("schedule", ["periodic", "sequence"])
def test_converges_over_dds(schedule, paper_tables, tmp_path):
    # 50 Hz at twice real time: the node gets 100 samples per wall-clock second, as at 100 Hz in real
    # time (at 3x and 100 Hz a loaded 2-core machine made it drop best-effort samples). The property
    # is in simulated time and does not depend on the rate: the periodic table's error 20 s in is
    # 3.3e-4 e0 at 100 Hz and 3.0e-4 e0 at 50 Hz (the same run in process, noise-free).
    res = demo.run(schedule, duration=21.0, time_scale=2.0, rate=50.0, init="zeros",
                   gain_table=paper_tables[schedule], out=None, quiet=True)
    t, err, e0 = res["t"], res["err"], res["e0"]
    assert e0 > 1.0                                           # zeros vs. the scene: ||x(0)|| ~ 4.3
    # every measurement answered. The inputs are best effort: on a loaded 2-core machine loopback
    # dropped 1.8 % of them once (1032 of 1051 answered); that the node answers every sample it
    # receives is checked where the count of received samples is known (test_fail_node.py)
    assert res["n_state"] >= 0.97 * res["n_truth"], (res["n_state"], res["n_truth"])
    assert len(res["stamps"]) == res["n_state"]               # every estimate carries a measurement's stamp
    assert t[-1] >= 20.0
    i20 = int(np.searchsorted(t, 20.0 - 1e-9))
    rel = err[i20:] / e0
    assert rel[0] < 1e-3, f"relative error {rel[0]:.2e} at t = {t[i20]:.2f} s"
    assert rel.max() < 1e-3, f"relative error up to {rel.max():.2e} after 20 s"
    assert err[0] / e0 > 0.5                                  # it did start far away
    # the published exact bound covers the published error at every answered measurement: with
    # innovation hold the node's error map is exact for noise-free samples, also when DDS drops one
    exact = res["exact"]
    assert np.all(exact > 0)
    assert np.all(err <= exact * (1 + 1e-6) + 1e-12), float(np.max(err / exact))
