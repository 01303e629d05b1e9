"""Acceptance of the measurement seam: a control researcher's own system (config/cart_pair.yaml,
not camera/target: one geometry_msgs/PointStamped topic per channel) goes from its YAML through
the Kalman design, the bag tools and, over DDS, camera_sim and the estimator, and converges under
the published exact bound with every sample tested for consistency (no false alarm)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from refusals import node_main

from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.report import load_report

REPO = Path(__file__).resolve().parents[2]
SYSTEM = str(REPO / "config" / "cart_pair.yaml")
X0 = (1.0, 0.2, -0.5, 0.1)
RATE = 50.0
PERIODIC = {"schedule.mode": "periodic", "schedule.tau": [2.0], "schedule.s": [0.6]}


@pytest.fixture(scope="module")
def cart_table(run_cache):
    """``switchobs design config/cart_pair.yaml --cycle 2,0.6 --gains kalman --rate 50``, as a user runs it,
    once per test run (the workers share it)."""
    def make(d):
        r = subprocess.run([sys.executable, "-m", "switchobs_core.cli", "design", SYSTEM, "--cycle", "2,0.6",
                            "--gains", "kalman", "--rate", str(RATE), "-o", str(d / "gains.json")],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
    return str(run_cache("cart_table", make) / "gains.json")


def _converged(err, exact):
    assert (exact > 0).all() and not (err > exact * (1 + 1e-9)).any()     # the guarantee, every sample
    assert err[0] > 0.3 and err[-1] < 1e-9 * err[0], (err[0], err[-1])


def test_own_system_through_the_bag_tools(tmp_path, cart_table):
    generate(tmp_path / "in", GenerateConfig(system=SYSTEM, schedule="periodic:2,0.6", duration=30.0, rate=RATE,
                                             initial_state=X0, extended=True), "mcap")
    params = estimator_params(overrides={"system": SYSTEM, "gain_table": cart_table, **PERIODIC,
                                         "e0": float(np.linalg.norm(X0)) * 1.01, "consistency.check": "always"})
    res = estimate(tmp_path / "in", params, out=tmp_path / "est")
    assert res.updates == 1501 and not res.rejected and res.inconsistent == 0 and res.bound_valid
    assert res.accepted == {"left/point": 901, "right/point": 600}       # one topic per channel, by the schedule
    (p,) = load_report(tmp_path / "est", "/estimator").passes
    _converged(p.err, p.exact)


@pytest.mark.parametrize("source,needle", [
    ("{topic: left/point, type: geometry_msgs/PointStamped, channel: 1, fields: [point.w], rows: [0]}", "point.w"),
    ("{topic: left/point, type: geometry_msgs/Wrench, channel: 1, fields: [force.x], rows: [0]}", "Wrench"),
    ("{topic: left/point, type: geometry_msgs/PointStamped, channel: 1, fields: [point.x], rows: [3]}", "rows"),
    ("{topic: 'left point', type: geometry_msgs/PointStamped, channel: 1, fields: [point.x], rows: [0]}", "topic"),
    ("{topic: both/point, type: geometry_msgs/PointStamped, fields: [point.x], rows: [0]}", "channel"),
])
def test_bad_specification_stops_start_up_with_one_line(tmp_path, cart_table, source, needle):
    """A wrong input specification (a field the type lacks, an unknown type, a row out of range,
    an invalid topic name, two channels on one topic without a channel topic): the estimator
    refuses to start, exit code != 0, one line naming it, no traceback."""
    from tools.launch import ros_args

    bad = tmp_path / "inputs.yaml"
    bad.write_text(f"inputs:\n  sources:\n    - {source}\n")
    r = node_main("estimator", ros_args(params={"system": SYSTEM, "gain_table": cart_table, "inputs": str(bad),
                                                **PERIODIC}), timeout=120)
    assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
    ours = [ln for ln in r.stderr.splitlines() if ln.startswith("estimator: error:")]
    assert len(ours) == 1 and "input specification" in ours[0] and needle in ours[0], r.stderr


@pytest.mark.serial      # timed over DDS (time_scale > 1): alone under xdist (test/conftest.py)
@pytest.mark.slow
def test_own_system_over_dds(tmp_path, cart_table):
    from tools import demo

    res = demo.run("periodic", duration=20.0, time_scale=2.0, rate=RATE, init="zeros", gain_table=cart_table,
                   out=None, quiet=True, schedule_params=PERIODIC, system=SYSTEM, initial_state=X0,
                   extra_estimator={"consistency.check": "always"})
    assert res["failures"] == []
    assert res["n_state"] >= 0.99 * res["n_truth"]
    _converged(res["err"], res["exact"])
