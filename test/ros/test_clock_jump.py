"""Clock jumps under use_sim_time: a jump back (a looped replay) resets the estimator, which then
accepts the replay's older stamps again and answers them; diagnostics count the jump."""

from __future__ import annotations

import pytest
from rclpy.duration import Duration
from ros_harness import EstimatorIO, spin_until
from rosgraph_msgs.msg import Clock
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_ros import qos
from tools.launch import NodeProcess, ros_args

S = 1_000_000_000


@pytest.fixture(scope="module")
def estimator(paper_tables, tmp_path_factory):
    log = tmp_path_factory.mktemp("jump") / "estimator.log"
    p = NodeProcess("estimator", ros_args(params={
        "gain_table": paper_tables["periodic"], "use_sim_time": True, "diagnostics_period": 0.1,
        "e0": 5.0}), log=log)                     # the scene lies 2.2 m from the estimate 0: e0 covers it
    yield p
    assert p.stop() == 0, p.output()


def _clock(pub, ns):
    m = Clock()
    m.clock = mb.ns_to_stamp(ns)
    pub.publish(m)


def _run(io, node, pub_clock, t0_ns, count):
    """Publish /clock and a camera/target pair every 10 ms from t0; return their stamps."""
    stamps = []
    for k in range(1, count + 1):
        s = t0_ns + k * 10_000_000
        _clock(pub_clock, s)
        spin_until(node, lambda: False, 0.003)
        io.pub_camera.publish(mb.xy_to_pose((0.0, 0.0), s, "map"))
        io.pub_target.publish(mb.xy_to_pose((1.0, 2.0), s, "map"))
        spin_until(node, lambda: False, 0.005)
        stamps.append(s)
    return stamps


def test_clock_jump_back_resets_and_estimation_resumes(estimator, ros_node):
    io = EstimatorIO(ros_node)
    pub_clock = ros_node.create_publisher(Clock, "/clock", qos.CLOCK)
    assert io.wait_matched(), estimator.output()
    assert spin_until(ros_node, lambda: pub_clock.get_subscription_count() > 0, 10.0)
    _clock(pub_clock, 100 * S)
    io.pub_channel.publish(UInt8(data=1))
    # reliable: wait until the estimator acknowledged the channel (on a loaded machine the poses,
    # best effort, could otherwise arrive first and be rejected as no_channel)
    assert io.pub_channel.wait_for_all_acked(Duration(seconds=5.0))
    spin_until(ros_node, lambda: False, 0.3)
    first = _run(io, ros_node, pub_clock, 100 * S, 40)
    assert spin_until(ros_node, lambda: len(io.msgs["state"]) >= len(first), 10.0), estimator.output()
    # an older stamp without a clock jump is rejected (old_stamp), not used
    io.pub_camera.publish(mb.xy_to_pose((0.0, 0.0), 99 * S, "map"))
    spin_until(ros_node, lambda: False, 0.3)
    more = _run(io, ros_node, pub_clock, 100 * S + 400_000_000, 30)  # let a diagnostics period pass
    assert spin_until(ros_node, lambda: io.diag_values().get("rejected camera/pose old_stamp") == "1", 10.0)
    # the last samples wait up to reorder_window_ms for their channel to be certain (no channel
    # message follows them here): every one is answered before the jump
    assert spin_until(ros_node, lambda: len(io.msgs["state"]) >= len(first) + len(more), 10.0)
    n_before = len(io.msgs["state"])
    # the replay loops: the clock jumps back by about 50 s, stamps start over
    second = _run(io, ros_node, pub_clock, 50 * S, 40)
    n_after = n_before + len(second)          # (state and envelope: two topics, wait for both)
    assert spin_until(ros_node, lambda: min(len(io.msgs["state"]), len(io.msgs["envelope"])) >= n_after, 10.0), \
        estimator.output()
    answered = [mb.unpack_labelled(m).stamp_ns for m in io.msgs["state"][n_before:]]
    assert answered == second                            # every sample after the jump is answered
    # before the reset the exact bound is ||Phi|| e0 > 0; after it no bound is known: -1 (NO_BOUND)
    env = [mb.unpack_labelled(m) for m in io.msgs["envelope"]]
    assert all(e.values[-1] > 0 for e in env[:n_before])
    assert all(e.values[-1] == -1.0 for e in env[n_before:]) and len(env) == n_before + len(second)
    assert spin_until(ros_node, lambda: io.diag_values().get("clock jumps back (resets)") == "1", 10.0)
    d = io.diag_values()
    assert d["resets"] == "1" and d["last clock jump"].startswith("back by 50.")
    assert d["exact bound valid"].startswith("false (clock jumped back")
    assert d.get("rejected camera/pose old_stamp") == "1"  # nothing after the jump was rejected
