#!/usr/bin/env python
"""The estimator's messaging without its math (a benchmark's node, not a test): ``sink``.

``python bench/sink_node.py SYSTEM_FILE --ros-args -r __node:=estimator -p output.odometry_every:=5 ...``

Subscribes to exactly the estimator's inputs for SYSTEM_FILE's default interface (the channel
``camera/active_channel`` as ``switchobs_msgs/ActiveChannel``, reliable; ``camera/pose`` and
``target/pose`` as PoseStamped, sensor data: :mod:`switchobs_ros.qos`, the same profiles), and,
when both poses of a stamp have arrived, publishes what the estimator publishes for one answer,
with the estimator's own writers (:mod:`msg_bridge.raw`: serialised once, numbers rewritten in
place, published as bytes): ``~/state`` and ``~/envelope`` every answer, ``~/covariance``, one
odometry per body, ``~/state_estimate`` and ``~/error_bounds`` every ``output.*_every``-th answer
and ``~/markers`` every ``output.markers_every``-th (defaults as the estimator's), each only while
a subscription is matched, as the estimator does. The numbers are fixed (no estimation); each input
callback also takes the inputs already waiting, as the estimator's does. It spins the executor
:func:`switchobs_ros.runner.make_executor` gives (``SWITCHOBS_EXECUTOR``).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from switchobs_msgs.msg import ActiveChannel, ErrorBounds, StateEstimate
from visualization_msgs.msg import MarkerArray

import msg_bridge as mb
import switchobs_core as so
from msg_bridge.markers import RawMarkersWriter
from msg_bridge.raw import RawLabelledArrayWriter, RawOdometryBatch
from msg_bridge.typed import ErrorBoundsWriter, RawStateEstimateWriter
from switchobs_ros import qos
from switchobs_ros.demand import listened
from switchobs_ros.runner import make_executor

EVERY = {"odometry": 1, "covariance": 1, "typed": 1, "markers": 10}


class Sink(Node):
    """The estimator's subscriptions and publishers, fixed numbers (module docstring)."""

    def __init__(self, system_file: str):
        super().__init__("estimator")
        sys_ = so.load_system(system_file)
        self.every = {k: int(self.declare_parameter(f"output.{k}_every", v).value) for k, v in EVERY.items()}
        labels = tuple(sys_.state_labels)
        bodies = mb.bodies(labels)
        n = len(labels)
        self.x = np.linspace(-1.0, 1.0, n)
        self.P = np.eye(n) * 0.01
        self.env = np.ones(len(mb.envelope_labels(sys_.N, noise_bound=False)))
        self.w_state = RawLabelledArrayWriter(labels)
        self.w_env = RawLabelledArrayWriter(mb.envelope_labels(sys_.N, noise_bound=False))
        self.w_cov = RawLabelledArrayWriter(mb.covariance_labels(labels))
        self.w_odom = RawOdometryBatch(bodies, "map", [b.name for b in bodies])
        self.w_typed = (RawStateEstimateWriter(labels, "map"), ErrorBoundsWriter(sys_.N, "map", False))
        self.w_markers = RawMarkersWriter(bodies, "map")

        def pub(kind, topic):
            return self.create_publisher(kind, topic, qos.OUTPUT,
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        def sub(kind, topic, cb, profile):
            ev = SubscriptionEventCallbacks(incompatible_qos=lambda e: None, use_default_callbacks=False)
            return self.create_subscription(kind, topic, cb, profile, event_callbacks=ev)
        self.pub_state = pub(Float64MultiArray, "~/state")
        self.pub_env = pub(Float64MultiArray, "~/envelope")
        self.pub_cov = pub(Float64MultiArray, "~/covariance")
        self.pub_odom = [pub(Odometry, f"~/{b.name}/odom") for b in bodies]
        self.pub_typed = (pub(StateEstimate, "~/state_estimate"), pub(ErrorBounds, "~/error_bounds"))
        self.pub_markers = pub(MarkerArray, "~/markers")
        self.parts: dict[int, int] = {}
        self.k = 0
        self.hot = (sub(ActiveChannel, "camera/active_channel", self._drained(self._channel), qos.CHANNEL_SUB),
                    sub(PoseStamped, "camera/pose", self._drained(self._pose), qos.SENSOR_SUB),
                    sub(PoseStamped, "target/pose", self._drained(self._pose), qos.SENSOR_SUB))
        self.handles = (self._channel, self._pose, self._pose)

    def _drained(self, handle):
        def callback(msg, info) -> None:
            handle(msg)
            for _ in range(32):         # the inputs already waiting (as the estimator's _drain_inputs)
                took = False
                for s, h in zip(self.hot, self.handles):
                    with s.handle:
                        got = s.handle.take_message(s.msg_type, s.raw)
                    if got is not None:
                        h(got[0])
                        took = True
                if not took:
                    break
        return callback

    def _channel(self, msg) -> None:
        pass

    def _pose(self, msg: PoseStamped) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if self.parts.pop(stamp, None) is None:
            self.parts[stamp] = 1
            return
        self._answer(stamp)

    def _answer(self, stamp: int) -> None:
        k, ev = self.k, self.every
        self.k += 1
        self.pub_state.publish(self.w_state.msg(self.x, stamp))
        if listened(self.pub_env):
            self.pub_env.publish(self.w_env.msg(self.env, stamp))
        if ev["covariance"] and k % ev["covariance"] == 0 and listened(self.pub_cov):
            self.pub_cov.publish(self.w_cov.msg(self.P.ravel(), stamp))
        if ev["odometry"] and k % ev["odometry"] == 0 and any(on := [listened(p) for p in self.pub_odom]):
            for p, m, yes in zip(self.pub_odom, self.w_odom.msgs(self.x, stamp, self.P), on):
                if yes:
                    p.publish(m)
        if ev["typed"] and k % ev["typed"] == 0:
            if listened(self.pub_typed[0]):
                self.pub_typed[0].publish(self.w_typed[0].msg(self.x, stamp, self.P))
            if listened(self.pub_typed[1]):
                self.pub_typed[1].publish(self.w_typed[1].msg(self.env, stamp, True, "", ""))
        if ev["markers"] and k % ev["markers"] == 0 and listened(self.pub_markers):
            self.pub_markers.publish(self.w_markers.msg(self.x, stamp, self.P, 1.0, None))


def main() -> None:
    rclpy.init(args=sys.argv)
    argv = rclpy.utilities.remove_ros_args(sys.argv)
    node = Sink(argv[1])
    ex = make_executor()
    ex.add_node(node)
    print("sink ready", flush=True)
    try:
        ex.spin()
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
