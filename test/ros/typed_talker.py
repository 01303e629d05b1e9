"""A second process for test_typed_msgs: publishes StateEstimate, ErrorBounds and MarkerArray.

Message k (k = 1, 2, ...) has stamp ``k`` s and the content of :func:`content`, so the
listener can check every message it gets. Runs until SIGINT or ``--seconds``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from switchobs_msgs.msg import ErrorBounds, StateEstimate
from visualization_msgs.msg import MarkerArray

import msg_bridge as mb
from msg_bridge.markers import MarkersWriter
from msg_bridge.typed import ErrorBoundsWriter, StateEstimateWriter

LABELS = tuple(f"{b}.{q}" for b in ("camera", "agent1", "agent2") for q in ("p_x", "p_y", "v_x", "v_y"))
NS = "/typed_test"


def content(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x, P and the envelope values ``[z_1, z_2, paper_bound, exact_bound, noise_bound]`` of message k."""
    x = np.arange(12.0) + k
    P = np.diag(np.arange(1.0, 13.0)) + 0.25 * k * (np.eye(12, k=1) + np.eye(12, k=-1))
    env = np.array([0.5 * k, 0.25 * k, -1.0, 0.1 * k, 0.2 * k])
    return x, P, env


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    args = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("typed_talker")
    try:
        pubs = [node.create_publisher(t, f"{NS}/{n}", 10) for t, n in
                ((StateEstimate, "state_estimate"), (ErrorBounds, "error_bounds"), (MarkerArray, "markers"))]
        w_state = StateEstimateWriter(LABELS, "map")
        w_bounds = ErrorBoundsWriter(2, "map", noise_declared=True)
        w_markers = MarkersWriter(mb.bodies(LABELS), "map")
        end = time.monotonic() + args.seconds
        k = 0
        while time.monotonic() < end:
            k += 1
            x, P, env = content(k)
            s = k * 1_000_000_000
            pubs[0].publish(w_state.msg(x, s, P))
            pubs[1].publish(w_bounds.msg(env, s, valid=k % 2 == 0, why="" if k % 2 == 0 else f"odd {k}"))
            pubs[2].publish(w_markers.msg(x, s, P, bound=float(env[3]), active_body="agent1"))
            rclpy.spin_once(node, timeout_sec=0.05)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
