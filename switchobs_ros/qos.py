"""QoS profiles of the switchobs topics (docs/reference/topics.md).

* Sensor inputs (``camera/pose``, ``target/pose``): ``qos_profile_sensor_data`` (best effort,
  volatile; a best-effort subscriber also accepts reliable publishers). Publishers keep the
  profile's depth 5; the estimator's subscriptions keep the last ``SENSOR_SUB_DEPTH`` = 50
  samples, so a scheduling hiccup of the node (garbage collection, a busy core) delays
  samples instead of dropping them (measured: with depth 5 a loaded 2-core machine lost
  about 2-5 % of the samples at 300 samples/s).
* ``camera/active_channel``: **reliable**, volatile, keep last ``SENSOR_SUB_DEPTH``, as deep as
  the poses': a backlog that keeps the poses keeps their channel messages (camera_sim sends one
  per tick). Reliable keep-last delivery still loses messages under load: a message
  the reader's transport dropped is repaired only while the writer's history holds it
  (measured beside two busy loops, camera_sim at 200 ticks/s: 5-30 % of the channel messages
  lost, mostly one or two at a time, with keep last 50 on both sides as with 10 and 1). A lost
  first message of a new channel made the estimator attribute that channel's target poses to
  the previous one (errors of metres), so channel attribution (switchobs_ros.attribution)
  detects losses by the publisher's sequence numbers and drops the channel parts of samples
  sent in a gap instead of guessing.
  A reliable subscription does not match a best-effort publisher: publish the channel reliably
  (rclpy's default). camera_sim publishes it reliable + transient local so a late (transient-local)
  subscriber gets the current channel at once; a volatile subscriber (the estimator's) accepts that.
  **History for a network**: a reliable writer repairs a lost message only while its history still
  holds it, and a message lost on a network is found missing only when later ones arrive. A
  repair helps only within the estimator's reorder window (a later one finds the samples it governs
  answered: the bounds are withdrawn), so the channel publisher keeps one window of messages at its
  rate, ``rate x`` :data:`CHANNEL_WINDOW_S` (:func:`channel_pub`; 5 at camera_sim's 100 Hz), and not
  many more: a deep history turns losses, which attribution detects and handles without guessing,
  into late deliveries (measured beside two busy loops: the demo with a history of 10 or 100 had
  its bounds withdrawn and a final error of 1e-3 to 12 m; with 1, a pass). Measured over emulated
  links: bench/RESULTS.md (bench/bench_netns.py).
* Outputs (``~/state``, ``~/envelope``, odometry, ``sim/truth``): reliable, keep last 10
  (truth: 100, so a test collector misses nothing).
"""

from __future__ import annotations

import math

from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)

__all__ = ["CHANNEL_MIN_DEPTH", "CHANNEL_PUB", "CHANNEL_SUB", "CHANNEL_WINDOW_S", "CLOCK", "OUTPUT", "SENSOR", "TRUTH",
           "channel_pub"]

SENSOR = qos_profile_sensor_data
SENSOR_SUB_DEPTH = 50
SENSOR_SUB = QoSProfile(depth=SENSOR_SUB_DEPTH, reliability=qos_profile_sensor_data.reliability,
                        durability=qos_profile_sensor_data.durability, history=QoSHistoryPolicy.KEEP_LAST)
#: The reorder window (s) a channel publisher's history covers (``reorder_window_ms``'s default).
CHANNEL_WINDOW_S = 0.05
#: The smallest history of the channel publisher and subscription (messages).
CHANNEL_MIN_DEPTH = 1


def channel_pub(rate_hz: float, window_s: float = CHANNEL_WINDOW_S) -> QoSProfile:
    """The channel publisher's QoS at ``rate_hz`` messages per second: reliable, transient local, keep last
    ``max(CHANNEL_MIN_DEPTH, ceil(rate_hz * window_s))`` (module docstring: a network repairs a lost
    message only from the writer's history)."""
    depth = CHANNEL_MIN_DEPTH
    if math.isfinite(rate_hz) and rate_hz > 0:
        depth = max(depth, math.ceil(rate_hz * window_s))
    return QoSProfile(depth=depth, reliability=QoSReliabilityPolicy.RELIABLE,
                      durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)


CHANNEL_SUB = QoSProfile(depth=SENSOR_SUB_DEPTH, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE, history=QoSHistoryPolicy.KEEP_LAST)
#: A channel publisher at up to 100 messages per second.
CHANNEL_PUB = channel_pub(100.0)
OUTPUT = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
TRUTH = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE)
#: /clock as rclpy's TimeSource subscribes to it (reliable would also match; keep it simple).
CLOCK = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.BEST_EFFORT)
