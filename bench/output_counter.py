#!/usr/bin/env python
"""The estimator's optional outputs, counted by a light process of their own (a benchmark's
listener, not a test).

    python bench/output_counter.py SYSTEM_FILE COUNTS.json

Subscribes to every output of the estimator besides ``~/state`` for SYSTEM_FILE (envelope,
covariance, the typed messages, markers, one odometry per body: :func:`optional_outputs`), so
that the estimator builds and publishes each, and counts the messages on each: taken raw (never
deserialised) by ``switchobs_ros.executor.KeptWaitSetExecutor``. On SIGINT it writes
``{topic: count}`` to COUNTS.json. ``bench/bench_live_scale.py --counter process`` runs it, so
that the process which times the answers does not also take these messages.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def optional_outputs(system) -> tuple[tuple[str, type], ...]:
    """The estimator's outputs besides ``~/state``: (topic, message type)."""
    from nav_msgs.msg import Odometry
    from std_msgs.msg import Float64MultiArray
    from switchobs_msgs.msg import ErrorBounds, StateEstimate
    from visualization_msgs.msg import MarkerArray

    import msg_bridge as mb
    return (("/estimator/envelope", Float64MultiArray), ("/estimator/covariance", Float64MultiArray),
            ("/estimator/state_estimate", StateEstimate), ("/estimator/error_bounds", ErrorBounds),
            ("/estimator/markers", MarkerArray),
            *((f"/estimator/{b.name}/odom", Odometry) for b in mb.bodies(system.state_labels)))


def counting(node, topics: tuple[tuple[str, type], ...], profile) -> dict[str, int]:
    """Raw subscriptions of ``node`` to ``topics``, each counting its messages into the dict returned."""
    counts = dict.fromkeys((t for t, _ in topics), 0)
    for topic, kind in topics:
        def count(_raw: bytes, topic: str = topic) -> None:
            counts[topic] += 1
        node.create_subscription(kind, topic, count, profile, raw=True)
    return counts


def main() -> int:
    import rclpy
    from _receipt import RECEIVE
    from rclpy.executors import ExternalShutdownException

    import switchobs_core as so
    from switchobs_ros.executor import KeptWaitSetExecutor

    rclpy.init(args=sys.argv)
    argv = rclpy.utilities.remove_ros_args(sys.argv)
    node = rclpy.create_node("bench_output_counter")
    counts = counting(node, optional_outputs(so.load_system(argv[1])), RECEIVE)
    ex = KeptWaitSetExecutor()
    ex.add_node(node)
    print("output_counter ready", flush=True)
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        Path(argv[2]).write_text(json.dumps(counts))
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
