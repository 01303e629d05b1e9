"""QoS profiles of the switchobs topics (docs/reference/topics.md).

* Sensor inputs (``camera/pose``, ``target/pose``): ``qos_profile_sensor_data`` (best effort,
  volatile; a best-effort subscriber also accepts reliable publishers). Publishers keep the
  profile's depth 5; the estimator's subscriptions keep the last ``SENSOR_SUB_DEPTH`` = 50
  samples, so a scheduling hiccup of the node (garbage collection, a busy core) delays
  samples instead of dropping them (measured: with depth 5 a loaded 2-core machine lost
  about 2-5 % of the samples at 300 samples/s).
* ``camera/active_channel``: **reliable**, volatile, keep last ``SENSOR_SUB_DEPTH``, as deep as
  the poses' (it was 10): a backlog that keeps the poses keeps their channel messages (camera_sim
  sends one per tick). Reliable keep-last delivery still loses messages under load: a message
  the reader's transport dropped is repaired only while the writer's history holds it
  (measured beside two busy loops, camera_sim at 200 ticks/s: 5-30 % of the channel messages
  lost, mostly one or two at a time, with keep last 50 on both sides as with 10 and 1). A lost
  first message of a new channel made the estimator attribute that channel's target poses to
  the previous one (errors of metres), so channel attribution (switchobs_ros.attribution)
  detects losses by the publisher's sequence numbers and drops the channel parts of samples
  sent in a gap instead of guessing.
  A reliable subscription does not match a best-effort publisher: publish the channel reliably
  (rclpy's default). camera_sim publishes it reliable + transient local (depth 1) so a late
  estimator gets the current channel at once; a volatile subscriber accepts that.
* Outputs (``~/state``, ``~/envelope``, odometry, ``sim/truth``): reliable, keep last 10
  (truth: 100, so a test collector misses nothing).
"""

from __future__ import annotations

from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_profile_sensor_data,
)

__all__ = ["CHANNEL_PUB", "CHANNEL_SUB", "CLOCK", "OUTPUT", "SENSOR", "TRUTH"]

SENSOR = qos_profile_sensor_data
SENSOR_SUB_DEPTH = 50
SENSOR_SUB = QoSProfile(depth=SENSOR_SUB_DEPTH, reliability=qos_profile_sensor_data.reliability,
                        durability=qos_profile_sensor_data.durability, history=QoSHistoryPolicy.KEEP_LAST)
CHANNEL_SUB = QoSProfile(depth=SENSOR_SUB_DEPTH, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE, history=QoSHistoryPolicy.KEEP_LAST)
CHANNEL_PUB = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)
OUTPUT = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
TRUTH = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE)
#: /clock as rclpy's TimeSource subscribes to it (reliable would also match; keep it simple).
CLOCK = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.BEST_EFFORT)
