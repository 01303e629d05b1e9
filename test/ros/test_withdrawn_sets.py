"""While the pipeline publishes no bound (withdrawn: noisy samples without a declared ``noise.max``, a
bias alarm), the observer's rigorous sets are not propagated (``bounds_withdrawn`` set by the
pipeline), and nothing published changes: the estimates, the envelopes (the paper's and the -1 of
the withdrawn bounds), the bounds re-certified from data and every counter are those of the same
run with the sets propagated throughout (``ErrorBounds.withdraw`` made a no-op)."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.bounds.rigorous import RoundingBound
from switchobs_core.runtime.error_bounds import ErrorBounds
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate

CASES = {
    # noise of 1 mm, no noise.max: the first sample beyond the noise-free bound withdraws for good
    "undeclared": (GenerateConfig(rate=50.0, duration=6.0, noise_std=1e-3), {}),
    # a 5 cm bias on the target poses from 2 s to 3 s: withdrawn by the bias test, re-certified from data
    "bias": (GenerateConfig(rate=50.0, duration=8.0, noise_std=0.01, noise_max=0.03, extended=True,
                            bias=(2.0, 3.0, 0.05)),
             {"gain_family": "kalman", "noise.measurement_std": 0.01, "noise.process_std": 0.01, "noise.max": 0.03,
              "e0": 10.0}),
}


def _run(d, name, params, monkeypatch, propagate_all: bool):
    steps = []      # per step of the sets (the LMI gains' step, the Kalman table's fused map): propagated or not

    def counted(f):
        def g(self, *a, **k):
            steps.append(not self.withdrawn)
            return f(self, *a, **k)
        return g

    with monkeypatch.context() as mp:
        mp.setattr(RoundingBound, "step", counted(RoundingBound.step))
        mp.setattr(RoundingBound, "fused", counted(RoundingBound.fused))
        if propagate_all:
            mp.setattr(ErrorBounds, "withdraw", lambda self, why: None)
        res = estimate(d / "in", estimator_params(overrides={"rate": 50.0, **params}), out=d / name)
    return res, steps


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_sets_rest_while_no_bound_is_published_and_nothing_published_changes(tmp_path, monkeypatch, case):
    config, params = CASES[case]
    generate(tmp_path / "in", config, "mcap")
    ours, steps = _run(tmp_path, "ours", params, monkeypatch, False)
    full, steps_full = _run(tmp_path, "full", params, monkeypatch, True)
    withdrawn = (ours.envelope[:, -1] == -1.0)
    assert withdrawn.any()
    assert sum(steps) < sum(steps_full)     # fewer steps of the sets propagated
    np.testing.assert_array_equal(ours.stamps, full.stamps)
    np.testing.assert_array_equal(ours.x_hat, full.x_hat)        # bit for bit
    np.testing.assert_array_equal(ours.envelope, full.envelope)
    for key in ("bound_valid", "bound_invalid_why", "recertifications", "recertified", "bias_alarms", "inconsistent",
                "updates", "rejected", "unanswered"):
        assert getattr(ours, key) == getattr(full, key), key
    if case == "bias":
        assert ours.recertifications >= 1 and ours.bound_valid and (ours.envelope[-50:, -1] > 0).all()
