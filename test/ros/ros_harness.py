"""Helpers of the ROS tests: spin until a condition, an estimator process, a test node's I/O."""

from __future__ import annotations

import time
from collections import defaultdict

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from std_msgs.msg import Float64MultiArray, UInt8
from std_srvs.srv import Trigger

from switchobs_ros import qos


def spin_until(node, cond, timeout: float, step: float = 0.02) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        rclpy.spin_once(node, timeout_sec=step)
    return cond()


class EstimatorIO:
    """The test's side of an estimator named ``estimator``: input publishers, output subscribers."""

    BODIES = ("camera", "agent1", "agent2")

    def __init__(self, node, ns: str = "/estimator"):
        self.node = node
        self.pub_channel = node.create_publisher(UInt8, "camera/active_channel", qos.CHANNEL_PUB)
        self.pub_camera = node.create_publisher(PoseStamped, "camera/pose", qos.SENSOR)
        self.pub_target = node.create_publisher(PoseStamped, "target/pose", qos.SENSOR)
        self.msgs = defaultdict(list)

        def keep(topic):
            return lambda m: self.msgs[topic].append(m)

        self.subs = [
            node.create_subscription(Float64MultiArray, f"{ns}/state", keep("state"), qos.TRUTH),
            node.create_subscription(Float64MultiArray, f"{ns}/envelope", keep("envelope"), qos.TRUTH),
            node.create_subscription(DiagnosticArray, "/diagnostics", keep("diagnostics"), qos.OUTPUT),
        ] + [node.create_subscription(Odometry, f"{ns}/{b}/odom", keep(b), qos.TRUTH) for b in self.BODIES]
        # not among self.subs (wait_matched): an estimator with publish_covariance false has no publisher
        self.sub_cov = node.create_subscription(Float64MultiArray, f"{ns}/covariance", keep("covariance"), qos.TRUTH)
        self.reset_client = node.create_client(Trigger, f"{ns}/reset")

    def wait_matched(self, timeout: float = 20.0) -> bool:
        def ok():
            return (all(p.get_subscription_count() > 0 for p in (self.pub_channel, self.pub_camera, self.pub_target))
                    and all(self.node.count_publishers(s.topic_name) > 0 for s in self.subs))
        return spin_until(self.node, ok, timeout)

    def diag_values(self) -> dict[str, str]:
        """Key/values of the latest /diagnostics message of the estimator (all statuses merged)."""
        for arr in reversed(self.msgs["diagnostics"]):
            if any("estimator" in s.name for s in arr.status):
                return {kv.key: kv.value for s in arr.status if "estimator" in s.name for kv in s.values}
        return {}


def start_feed(io: EstimatorIO, channel: int, n: int, period_ns: int = 10_000_000) -> list[int]:
    """Send the channel, wait until the estimator acknowledged it, and return ``n`` stamps from
    now on at ``period_ns`` (the usual start of a test that feeds measurements)."""
    io.pub_channel.publish(UInt8(data=channel))
    io.pub_channel.wait_for_all_acked(Duration(seconds=5.0))
    spin_until(io.node, lambda: False, 0.2)
    base = time.time_ns()
    return [base + k * period_ns for k in range(1, n + 1)]
