"""switchobs_ros.outputs.send: serialised bytes reach a subscriber exactly as ``Publisher.publish``
sends them, and so does a raw writer's own buffer (``write``), rewritten after each send; a message
object goes through ``Publisher.publish``."""

from __future__ import annotations

import time

import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from msg_bridge.raw import RawLabelledArrayWriter
from switchobs_ros.executor import KeptWaitSetExecutor
from switchobs_ros.outputs import send

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def test_bytes_and_messages_arrive_as_publish_sends_them():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("output_send", context=context)
    ex = KeptWaitSetExecutor(context=context)
    try:
        ex.add_node(node)
        got = []
        node.create_subscription(Float64MultiArray, "/output_send", got.append, RELIABLE, raw=True)
        pub = node.create_publisher(Float64MultiArray, "/output_send", RELIABLE)
        end = time.monotonic() + 20.0       # (only ends a broken run: nothing here is timed)
        while pub.get_subscription_count() == 0 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        first = Float64MultiArray(data=[1.5, -2.0, 3.25])
        second = Float64MultiArray(data=[4.0])
        raw = serialize_message(first)
        send(pub, raw)                      # bytes: the handle's publish_raw
        send(pub, second)                   # a message: Publisher.publish
        pub.publish(raw)                    # rclpy's own path, for comparison
        # a writer's own buffer (write: not copied), rewritten right after: each sent as it was
        writer = RawLabelledArrayWriter(("a", "b"))
        buf = writer.write(np.array([7.0, 8.0]), 5_000_000_001)
        want = bytes(buf)
        send(pub, buf)
        writer.write(np.array([9.0, -1.0]), 6_000_000_002)
        send(pub, buf)
        while len(got) < 5 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert got[0] == raw and got[2] == raw          # the bytes as given
        assert got[3] == want and got[4] == bytes(buf) and got[3] != got[4]
        assert got[4] == writer.msg(np.array([9.0, -1.0]), 6_000_000_002)
        # (a message serialised by the middleware may differ from ours in its alignment padding)
        assert [list(deserialize_message(b, Float64MultiArray).data) for b in got[:3]] == [[1.5, -2.0, 3.25], [4.0],
                                                                                          [1.5, -2.0, 3.25]]
    finally:
        node.destroy_node()
        ex.shutdown()
        rclpy.try_shutdown(context=context)
