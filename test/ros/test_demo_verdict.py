"""The demo's verdict (tools/demo.py): a published estimate above the published exact bound, or a
noise-free final error not below 1e-4 of the initial one, fails the demo; withdrawn bounds (-1)
and noisy runs do not."""

from __future__ import annotations

import numpy as np

from tools.demo import FINAL_FRACTION, verdict


def _res(err, exact, noise=0.0, e0=1.0):
    err = np.asarray(err, dtype=float)
    return {"t": np.arange(err.size) * 0.01, "err": err, "exact": np.asarray(exact, dtype=float), "e0": e0,
            "noise": noise}


def test_a_converged_run_under_its_bound_passes():
    assert verdict(_res([1.0, 1e-3, 1e-6], [2.0, 2e-3, 2e-6])) == []


def test_an_estimate_above_the_bound_fails_naming_the_first():
    out = verdict(_res([1.0, 3e-3, 1e-6, 5e-6], [2.0, 2e-3, 2e-6, 2e-6]))
    assert len(out) == 1 and out[0].startswith("2 of 4 published estimates are above") and "t = 0.01 s" in out[0]


def test_a_withdrawn_bound_is_no_failure_but_no_convergence_is():
    assert verdict(_res([1.0, 0.5, 1e-6], [2.0, -1.0, -1.0])) == []
    out = verdict(_res([1.0, 0.5, 0.1], [2.0, 1.0, 0.2]))
    assert len(out) == 1 and f"not below {FINAL_FRACTION:g}" in out[0]


def test_noisy_runs_are_not_judged_by_the_noise_free_bound():
    assert verdict(_res([1.0, 0.5, 0.1], [2.0, 1e-3, 1e-6], noise=1e-3)) == []
