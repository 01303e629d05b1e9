"""Acceptance: a generated bag replayed LIVE through the estimator process over DDS with sim time
gives, message for message, the estimates of the offline run over the same bag; a looped replay
resets the estimator at the jump back and reaches the same accuracy again."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from std_msgs.msg import Float64MultiArray

import msg_bridge as mb
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate, scenario_ticks
from switchobs_ros.bag.io import BagIn, deserialize
from switchobs_ros.bag.report import load_report
from tools.live_replay import OUTPUT_TOPICS, live_replay


def _recorded(path, topic, order="file"):
    with BagIn(path) as bag:
        return [mb.unpack_labelled(deserialize(m, Float64MultiArray)) for m in bag.messages([topic], order=order)]


def _compare(live, off, what):
    stamps = [a.stamp_ns for a in live]
    assert stamps == off.stamps.tolist(), f"{what}: stamps differ (live {len(stamps)}, offline {off.stamps.size})"
    return np.array([a.values for a in live])


@pytest.mark.slow
def test_live_replay_equals_offline_mcap(paper_tables, tmp_path):
    cfg = GenerateConfig(duration=5.0, noise_std=0.01, seed=11)
    generate(tmp_path / "in", cfg, "mcap")
    params = {"gain_table": paper_tables["periodic"], "e0": 5.0}
    live_replay(tmp_path / "in", tmp_path / "rec", tmp_path, params)
    off = estimate(tmp_path / "in", estimator_params(overrides=params))
    assert off.stamps.size == round(cfg.duration * cfg.rate) + 1 and off.partial_updates == 0
    x = _compare(_recorded(tmp_path / "rec", "/estimator/state"), off, "state")
    e = _compare(_recorded(tmp_path / "rec", "/estimator/envelope"), off, "envelope")
    np.testing.assert_allclose(x, off.x_hat, rtol=0, atol=1e-9)
    np.testing.assert_allclose(e, off.envelope, rtol=0, atol=1e-9)
    with BagIn(tmp_path / "rec") as bag:
        odo = [deserialize(m, Odometry) for m in bag.messages(["/estimator/agent1/odom"], order="file")]
    assert [mb.stamp_to_ns(o.header.stamp) for o in odo] == off.stamps.tolist()
    assert np.abs(np.array([o.pose.pose.position.x for o in odo]) - off.x_hat[:, 4]).max() <= 1e-9


@pytest.mark.slow
def test_looped_live_replay_sqlite_resets_and_converges_again(paper_tables, tmp_path):
    cfg = GenerateConfig(duration=6.0, noise_std=0.01, seed=5)
    generate(tmp_path / "in", cfg, "sqlite3")
    # the replay's loop and reset, not the data tests: 1 cm Gaussian noise, no noise.max and the
    # default 1 mm noise model, which the consistency test and the bias test (test_consistency.py,
    # test_recovery_bag.py) would rightly hold against the noise-free bound
    params = {"gain_table": paper_tables["periodic"], "e0": 5.0, "diagnostics_period": 0.5,
              "consistency.check": "never", "consistency.bias": False}
    live_replay(tmp_path / "in", tmp_path / "rec", tmp_path, params, loops=2,
                record_topics=(*OUTPUT_TOPICS, "/sim/truth"))
    off = estimate(tmp_path / "in", estimator_params(overrides=params))
    live = _recorded(tmp_path / "rec", "/estimator/state")
    n = off.stamps.size
    assert len(live) == 2 * n, (len(live), n)             # no estimate missing in either pass
    for k in range(2):                                    # each pass is the offline run, sample for sample
        x = _compare(live[k * n:(k + 1) * n], off, f"pass {k + 1}")
        np.testing.assert_allclose(x, off.x_hat, rtol=0, atol=1e-9)
    with BagIn(tmp_path / "rec") as bag:
        diag = [deserialize(m, DiagnosticArray) for m in bag.messages(["/diagnostics"], order="file")]
    vals = {kv.key: kv.value for s in diag[-1].status if "estimator" in s.name for kv in s.values}
    assert vals["clock jumps back (resets)"] == "1" and vals["resets"] == "1"
    assert vals["last clock jump"].startswith("back by 6")
    assert vals["rejected total"] == "0"
    # the report splits the recording into its two passes: the same accuracy again
    rep = load_report(tmp_path / "rec")
    assert len(rep.passes) == 2
    # each pass is matched with its own envelopes (the stamps repeat): pass 1 has the verified bound,
    # pass 2, after the reset, none (-1: the new initial error is unknown)
    assert np.all(rep.passes[0].exact > 0) and np.all(rep.passes[1].exact == -1.0)
    truth = {s: np.asarray(m.data[2:]) for s, msgs in scenario_ticks(cfg) for t, m in msgs if t == "/sim/truth"}
    final = np.linalg.norm(off.x_hat[-1] - truth[int(off.stamps[-1])])
    assert final < 0.2 * np.linalg.norm(off.x_hat[0] - truth[int(off.stamps[0])])
    for p in rep.passes:
        assert p.e_final == pytest.approx(final, rel=1e-9)
        assert p.e_first > 4 * p.e_final                  # each pass starts over from the initial estimate


def test_record_on_sim_time_count_limit_and_sigterm(ros_node, tmp_path):
    """record: receive time on the node's sim clock (/clock), --count stops it; SIGTERM closes the bag."""
    import signal
    import sys
    import time

    from ros_harness import spin_until
    from rosgraph_msgs.msg import Clock

    from switchobs_ros import qos
    from tools.launch import NodeProcess

    cmd = [sys.executable, "-m", "switchobs_ros.bag"]
    rec = NodeProcess("record", ["record", str(tmp_path / "a"), "--topics", "/sim/truth", "--count", "20",
                                 "--ros-args", "-p", "use_sim_time:=true"], cmd=cmd, log=tmp_path / "a.log")
    rec2 = NodeProcess("record", ["record", str(tmp_path / "b"), "--topics", "/sim/truth", "--storage", "sqlite3"],
                       cmd=cmd, log=tmp_path / "b.log")
    pub = ros_node.create_publisher(Float64MultiArray, "/sim/truth", qos.TRUTH)
    clk = ros_node.create_publisher(Clock, "/clock", qos.CLOCK)
    assert spin_until(ros_node, lambda: pub.get_subscription_count() >= 2 and clk.get_subscription_count() >= 1,
                      20.0), rec.output() + rec2.output()
    spin_until(ros_node, lambda: False, 0.5)
    sent = []
    for k in range(40):
        t = 50 * 10**9 + k * 10**8
        clk.publish(Clock(clock=mb.ns_to_stamp(t)))
        spin_until(ros_node, lambda: False, 0.02)
        pub.publish(mb.labelled_array([float(k)], ["k"], t))
        sent.append(t)
        spin_until(ros_node, lambda: False, 0.02)
    assert rec.wait(20.0) == 0, rec.output()            # --count 20 reached
    rec2.proc.send_signal(signal.SIGTERM)
    assert rec2.wait(20.0) == 0, rec2.output()
    rec.stop()
    rec2.stop()
    with BagIn(tmp_path / "a") as bag:
        msgs = bag.messages()
    assert len(msgs) == 20
    # log time = the sim clock at receipt: the /clock sent just before (or, were that best-effort
    # /clock sample lost, the one before it), never the system time
    lag = [mb.unpack_labelled(deserialize(m, Float64MultiArray)).stamp_ns - m.log_ns for m in msgs]
    assert set(lag) <= {0, 10**8} and lag.count(0) >= 15, lag
    with BagIn(tmp_path / "b") as bag:
        assert bag.storage == "sqlite3" and bag.counts["/sim/truth"] == 40
        vals = [mb.unpack_labelled(deserialize(m, Float64MultiArray)).values[0] for m in bag.messages()]
    assert vals == [float(k) for k in range(40)]
    now = time.time_ns()
    with BagIn(tmp_path / "b") as bag:                   # without use_sim_time: the system clock
        assert all(abs(m.log_ns - now) < 120 * 10**9 for m in bag.messages())
