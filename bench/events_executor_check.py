"""Reproduction: rclpy.experimental.EventsExecutor delivers no subscription callback (not a test).

``python bench/events_executor_check.py`` subscribes ``/evt`` with the EventsExecutor for 6 s and
prints how many messages arrived; publish to ``/evt`` meanwhile (e.g. a SingleThreadedExecutor
node, 30 std_msgs/String at 20 Hz). With the PyPI wheels here (rclpy 7.1.6, rmw_fastrtps_cpp
8.4.3) it prints ``total 0``; the same node under SingleThreadedExecutor receives all 30. The
estimator therefore spins a SingleThreadedExecutor (switchobs_ros/runner.py).
"""

from __future__ import annotations

import os
import threading
import time

import rclpy
from rclpy.experimental import EventsExecutor
from std_msgs.msg import String


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("evsub")
    got: list[int] = []
    node.create_subscription(String, "/evt", lambda m: got.append(1), 10)
    ex = EventsExecutor()
    ex.add_node(node)

    def stop() -> None:
        time.sleep(6)
        print("total", len(got), flush=True)
        os._exit(0)

    threading.Thread(target=stop, daemon=True).start()
    ex.spin()


if __name__ == "__main__":
    main()
