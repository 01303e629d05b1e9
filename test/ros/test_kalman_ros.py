"""The Kalman gain families through the ROS side: the offline bag estimator and the node take the
family from the table (or from ``gain_family``), publish the error covariance on ``~/covariance``
and in the odometry, and are as accurate as the online filter, far more than the paper's gains."""

from __future__ import annotations

import numpy as np
import pytest
from ros_harness import EstimatorIO, spin_until, start_feed

import msg_bridge as mb
from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.noise import NoiseModel
from switchobs_core.model.scenarios import load_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import kalman_table
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate, scenario_ticks
from tools.launch import NodeProcess, ros_args

NOISE, PROCESS, RATE = 0.01, 0.01, 100.0


@pytest.fixture(scope="module")
def kalman_setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("kalman")
    cfg = GenerateConfig(duration=20.0, noise_std=NOISE, process_noise=PROCESS, seed=5, rate=RATE)
    generate(d / "bag", cfg, "mcap")
    sys_ = load_system("paper")
    noise = NoiseModel.for_system(sys_, measurement_std=NOISE, process_std=PROCESS)
    table = kalman_table(sys_, [design_kalman(sys_, Cycle.from_ts(2.0, 0.6), RATE, noise)])
    truth = {s: np.asarray(m.data[2:]) for s, msgs in scenario_ticks(cfg) for t, m in msgs if t == "/sim/truth"}
    return d, str(table.save(d / "kalman.json")), truth


def _rms(res, truth, after_ns):
    e = [x - truth[s] for s, x in zip(res.stamps, res.x_hat) if s >= after_ns]
    return float(np.sqrt(np.mean(np.sum(np.square(e), axis=1))))


def test_bag_estimate_with_kalman_table_matches_online_and_beats_lmi(kalman_setup, paper_tables):
    d, ktable, truth = kalman_setup
    common = {"e0": 5.0, "noise.measurement_std": NOISE, "noise.process_std": PROCESS}
    lmi = estimate(d / "bag", estimator_params(overrides={"gain_table": paper_tables["periodic"], **common}))
    kal = estimate(d / "bag", estimator_params(overrides={"gain_table": ktable, **common}), out=d / "est")
    onl = estimate(d / "bag", estimator_params(overrides={"gain_table": ktable, "gain_family": "kalman-online",
                                                          **common}))
    t10 = int(lmi.stamps[0] + 10e9)
    r_lmi, r_kal, r_onl = (_rms(r, truth, t10) for r in (lmi, kal, onl))
    assert r_kal <= 1.02 * r_onl, (r_kal, r_onl)
    assert r_lmi >= 1.3 * r_kal, (r_lmi, r_kal)
    # the covariance is the filter's: the average NEES over the last 10 s near n = 12 (one run,
    # correlated samples: a loose band; the Monte Carlo band test is in test/core)
    nees = [float((x - truth[s]) @ np.linalg.solve(P, x - truth[s]))
            for s, x, P in zip(kal.stamps, kal.x_hat, kal.P) if s >= t10]
    assert 6.0 < np.mean(nees) < 24.0, np.mean(nees)
    # the LMI gains get the covariance of their own error under the same noise model
    nees_lmi = [float((x - truth[s]) @ np.linalg.solve(P, x - truth[s]))
                for s, x, P in zip(lmi.stamps, lmi.x_hat, lmi.P) if s >= t10]
    assert 6.0 < np.mean(nees_lmi) < 24.0, np.mean(nees_lmi)


@pytest.fixture(scope="module")
def kalman_node(kalman_setup, tmp_path_factory):
    _, ktable, _ = kalman_setup
    log = tmp_path_factory.mktemp("kest") / "estimator.log"
    p = NodeProcess("estimator", ros_args(params={"gain_table": ktable, "diagnostics_period": 0.3}), log=log)
    yield p
    assert p.stop() == 0, p.output()


def test_node_with_kalman_table_publishes_covariance(kalman_node, ros_node):
    io = EstimatorIO(ros_node)
    assert io.wait_matched(), kalman_node.output()
    stamps = start_feed(io, 1, 30)      # the table's 100 Hz grid
    for s in stamps:
        io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), s, "map"))
        io.pub_target.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
        spin_until(ros_node, lambda: False, 0.005)
    assert spin_until(ros_node, lambda: len(io.msgs["covariance"]) >= len(stamps)
                      and len(io.msgs["agent1"]) >= len(stamps), 10.0), kalman_node.output()
    cov = mb.unpack_labelled(io.msgs["covariance"][-1])
    assert cov.stamp_ns == stamps[-1] and len(cov.values) == 144 and cov.labels[1] == "camera.p_x|camera.p_y"
    P = cov.values.reshape(12, 12)
    assert np.allclose(P, P.T) and np.all(np.linalg.eigvalsh(P) > 0)
    odom = io.msgs["agent1"][-1]
    pose = np.reshape(odom.pose.covariance, (6, 6))
    assert pose[0, 0] == P[4, 4] and pose[1, 1] == P[5, 5] and pose[2, 2] == mb.UNESTIMATED_VARIANCE
    assert np.reshape(odom.twist.covariance, (6, 6))[0, 0] == P[6, 6]
    # the camera is measured at every sample: its position variance has fallen far below P0 = 100
    assert P[0, 0] < 1e-3
    assert spin_until(ros_node, lambda: io.diag_values().get("gain family") == "kalman", 5.0)
    d = io.diag_values()
    assert d["kalman table departures (online recursion)"] == "0" and d["kalman gains now"] == "table"
    assert d["kalman table gaps (missing samples served on the table's grid)"] == "0"
