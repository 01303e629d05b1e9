"""The estimator node in its own process: outputs, stamps, frames, layout, diagnostics, reset,
and rejection of bad messages (the node keeps running and counts them by reason)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from ros_harness import EstimatorIO, spin_until, start_feed
from std_msgs.msg import UInt8
from std_srvs.srv import Trigger

import msg_bridge as mb
from tools.launch import NodeProcess, ros_args

LABELS = tuple(f"{b}.{q}" for b in ("camera", "agent1", "agent2") for q in ("p_x", "p_y", "v_x", "v_y"))


@pytest.fixture(scope="module")
def estimator(paper_tables, tmp_path_factory):
    log = tmp_path_factory.mktemp("est") / "estimator.log"
    p = NodeProcess("estimator", ros_args(params={
        "gain_table": paper_tables["periodic"], "world_frame": "world_test", "input_frame_id": "world_test",
        "body_frames": ["cam_link", "a1_link", "a2_link"], "diagnostics_period": 0.5}), log=log)
    yield p
    rc = p.stop()
    assert rc == 0, p.output()


def _send(io, stamp_ns, cam, tgt, frame="world_test"):
    io.pub_camera.publish(mb.xy_to_pose(cam, stamp_ns, frame))
    io.pub_target.publish(mb.xy_to_pose(tgt, stamp_ns, frame))


def test_outputs_carry_stamp_frames_and_labels(estimator, ros_node):
    io = EstimatorIO(ros_node)
    assert io.wait_matched(), estimator.output()
    stamps = start_feed(io, 1, 20)
    for s in stamps:
        _send(io, s, (0.1, 0.2), (3.0, 1.0))
        spin_until(ros_node, lambda: False, 0.005)
    assert spin_until(ros_node, lambda: len(io.msgs["agent2"]) >= len(stamps), 10.0), estimator.output()
    state = [mb.unpack_labelled(m) for m in io.msgs["state"]]
    env = [mb.unpack_labelled(m) for m in io.msgs["envelope"]]
    assert [a.stamp_ns for a in state] == stamps          # one answer per measurement, its stamp
    assert [a.stamp_ns for a in env] == stamps
    assert all(a.labels == LABELS for a in state)
    assert all(a.labels == ("z_1", "z_2", "paper_bound", "exact_bound") for a in env)
    assert all(np.isfinite(a.values).all() for a in state + env)
    for body, child in zip(EstimatorIO.BODIES, ("cam_link", "a1_link", "a2_link")):
        odoms = io.msgs[body]
        assert [mb.stamp_to_ns(o.header.stamp) for o in odoms] == stamps
        assert all(o.header.frame_id == "world_test" and o.child_frame_id == child for o in odoms)
    # odometry is the state: agent1's position and velocity
    last, o = state[-1].values, io.msgs["agent1"][-1]
    assert (o.pose.pose.position.x, o.twist.twist.linear.y) == (last[4], last[7])
    # the estimate moves towards the measured positions (camera near (0.1, 0.2) after 0.2 s)
    assert abs(state[-1].values[0]) < abs(state[0].values[0] - 0.1) + 0.1

    # diagnostics: cycle, gains, rates, counts
    assert spin_until(ros_node, lambda: "updates" in io.diag_values()
                      and int(io.diag_values()["updates"]) >= len(stamps), 5.0)
    d = io.diag_values()
    assert d["channel"] == "1" and d["current cycle tau"] == "2" and d["current cycle s"] == "0.6"
    assert d["mode"] == "periodic" and "current gain norms |L_i|" in d
    assert int(d["camera/pose accepted"]) >= len(stamps)

    # ~/reset: the next sample restarts from the initial estimate at its own stamp
    assert io.reset_client.wait_for_service(timeout_sec=5.0)
    fut = io.reset_client.call_async(Trigger.Request())
    assert spin_until(ros_node, fut.done, 5.0)
    assert fut.result().success
    n0 = len(io.msgs["state"])
    s_new = stamps[0] - 5_000_000    # older than before the reset: accepted after it
    _send(io, s_new, (0.1, 0.2), (3.0, 1.0))
    assert spin_until(ros_node, lambda: len(io.msgs["state"]) > n0, 5.0)
    after = mb.unpack_labelled(io.msgs["state"][-1])
    assert after.stamp_ns == s_new
    np.testing.assert_array_equal(after.values, np.zeros(12))   # the initial estimate at the new origin


def test_bad_messages_rejected_counted_node_keeps_running(estimator, ros_node):
    io = EstimatorIO(ros_node)
    assert io.wait_matched(), estimator.output()
    io.pub_channel.publish(UInt8(data=2))
    spin_until(ros_node, lambda: False, 0.2)
    base = time.time_ns()
    good = iter(base + k * 10_000_000 for k in range(1, 1000))

    def good_pair():
        s = next(good)
        _send(io, s, (0.0, 0.0), (-2.0, 2.0))
        return s

    s_last = good_pair()
    bad = []
    for field, value in (("x", math.nan), ("y", math.inf), ("x", 1e300)):
        m = mb.xy_to_pose((0.0, 0.0), next(good), "world_test")
        setattr(m.pose.position, field, value)
        bad.append(m)
    bad.append(mb.xy_to_pose((0.0, 0.0), next(good), "other_frame"))
    bad.append(mb.xy_to_pose((0.0, 0.0), 0, "world_test"))                       # zero stamp
    bad.append(mb.xy_to_pose((0.0, 0.0), s_last, "world_test"))                  # duplicate
    bad.append(mb.xy_to_pose((0.0, 0.0), s_last - 1_000_000, "world_test"))      # older
    bad.append(mb.xy_to_pose((0.0, 0.0), time.time_ns() + 60 * 10**9, "world_test"))  # 60 s ahead
    ok = serialize_message(mb.xy_to_pose((0.0, 0.0), next(good), "world_test"))
    bad += [ok[:-8], b"\x00\x00" + ok[2:]]    # bytes: truncated, a big-endian label on little-endian content
    for m in bad:
        io.pub_target.publish(m)
        spin_until(ros_node, lambda: False, 0.01)
    for v in (0, 3, 255):
        io.pub_channel.publish(UInt8(data=v))
        spin_until(ros_node, lambda: False, 0.01)
    n0 = len(io.msgs["state"])
    s_after = good_pair()        # still answered
    assert spin_until(ros_node, lambda: any(mb.unpack_labelled(m).stamp_ns == s_after
                                            for m in io.msgs["state"][n0:]), 5.0), estimator.output()
    expected = {"non_finite": 2, "too_large": 1, "wrong_frame": 1, "zero_stamp": 1, "duplicate_stamp": 1,
                "old_stamp": 1, "future_stamp": 1, "bad_layout": 2}

    def counts_ok():
        d = io.diag_values()
        return (all(int(d.get(f"rejected target/pose {r}", 0)) >= n for r, n in expected.items())
                and int(d.get("rejected camera/active_channel bad_channel", 0)) >= 3)
    assert spin_until(ros_node, counts_ok, 5.0), io.diag_values()
    assert estimator.alive()
    assert all(np.isfinite(mb.unpack_labelled(m).values).all() for m in io.msgs["state"])
