"""The estimator node's own glue, in process: the reused output messages, the input drain
(``EstimatorMixin._drain_inputs``: messages already waiting are taken without another wait) and
the pairing timer, running only while a sample waits."""

from __future__ import annotations

import time

import numpy as np
from rclpy.parameter import Parameter
from ros_harness import EstimatorIO, spin_until
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_ros.estimator import EstimatorNode


def test_array_writer_gives_the_labelled_array_and_reuses_it():
    labels = ("a", "b", "c")
    w = mb.LabelledArrayWriter(labels)
    first = w.msg(np.array([1.5, -2.0, 3.25]), 12_345_678_901)
    ref = mb.labelled_array([1.5, -2.0, 3.25], labels, 12_345_678_901)
    assert first.layout == ref.layout
    assert list(first.data) == list(ref.data)
    again = w.msg(np.array([0.0, 1e300, -0.5]), 7)
    assert again is first                                 # one message, rewritten
    arr = mb.unpack_labelled(again)
    assert (arr.stamp_ns, arr.labels, arr.values.tolist()) == (7, labels, [0.0, 1e300, -0.5])


def _drain_until(node: EstimatorNode, cond, timeout: float = 10.0) -> bool:
    """Call the drain (the node is not spun) until ``cond`` holds; messages arrive asynchronously."""
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        node._drain_inputs()
        time.sleep(0.01)
    return cond()


def _on_channel_one(est, ros_node):
    """The test's input publishers, matched with the node, and channel 1 taken by it: ``(io, pipeline)``."""
    io = EstimatorIO(ros_node)
    assert spin_until(ros_node, lambda: all(p.get_subscription_count() > 0
                                            for p in (io.pub_channel, io.pub_camera, io.pub_target)), 20.0)
    pl = est.pipeline
    io.pub_channel.publish(UInt8(data=1))
    assert _drain_until(est, lambda: pl.channel == 1)
    return io, pl


def test_drain_takes_waiting_inputs_channel_first(paper_tables, ros_node):
    # the drain alone (no timer runs here): arrival order decides the channel (reorder window 0),
    # else the last sample would wait for the window's timer (test_attribution.py)
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("reorder_window_ms", value=0.0)])
    try:
        io, pl = _on_channel_one(est, ros_node)
        base = time.time_ns()
        stamps = [base + k * 10_000_000 for k in range(1, 6)]
        for s in stamps:
            io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), s, "map"))
            io.pub_target.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
        assert _drain_until(est, lambda: pl.updates == len(stamps))
        assert pl.accepted["camera/pose"] == pl.accepted["target/pose"] == len(stamps)
        assert pl.partial_updates == 0 and not pl.rejected
        assert pl.obs_ns == stamps[-1]
        # a deactivated node counts what it drains and ignores it
        est.answering = False
        io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), base + 10**9, "map"))
        assert _drain_until(est, lambda: est.ignored_inactive == 1)
        assert pl.updates == len(stamps)
    finally:
        est.destroy_node()


def test_channel_messages_reach_the_pipeline_with_their_sequence_numbers(paper_tables, ros_node):
    """The node passes the publisher's sequence number (rclpy's MessageInfo) with each channel
    message, by which the pipeline finds lost ones (test_attribution.py): consecutive numbers
    from one publisher, no loss counted."""
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"])])
    try:
        io = EstimatorIO(ros_node)
        assert spin_until(ros_node, lambda: io.pub_channel.get_subscription_count() > 0, 20.0)
        pl = est.pipeline
        for c in (1, 1, 2, 2, 1):
            io.pub_channel.publish(UInt8(data=c))
        assert _drain_until(est, lambda: len(pl.attribution.sequence_numbers) == 5)
        seq = pl.attribution.sequence_numbers
        assert None not in seq and np.all(np.diff(seq) == 1) and pl.lost_channel == 0
    finally:
        est.destroy_node()


def test_pairing_timer_runs_only_while_a_sample_waits(paper_tables, ros_node):
    """Idle (every sample answered, the channel type settled), the pairing timer is cancelled: it
    does not wake the executor. A lone camera pose arms it, and it answers the pose alone after
    ``pairing_timeout``; then it is cancelled again."""
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("reorder_window_ms", value=0.0),
                                             Parameter("pairing_timeout", value=0.1)])
    try:
        io, pl = _on_channel_one(est, ros_node)
        base = time.time_ns()
        for k in range(1, 4):
            s = base + k * 10_000_000
            io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), s, "map"))
            io.pub_target.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
        assert _drain_until(est, lambda: pl.updates == 3)
        assert spin_until(est, lambda: not est._channel_tentative and est.pair_timer.is_canceled(), 5.0)
        lone = base + 4 * 10_000_000
        io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), lone, "map"))      # its target never comes
        assert _drain_until(est, lambda: pl.accepted["camera/pose"] == 4)
        assert pl.updates == 3 and not est.pair_timer.is_canceled()
        assert spin_until(est, lambda: pl.updates == 4, 5.0)         # the timer answered it alone
        assert pl.partial_updates == 1 and pl.obs_ns == lone
        assert spin_until(est, lambda: est.pair_timer.is_canceled(), 2.0)
    finally:
        est.destroy_node()
