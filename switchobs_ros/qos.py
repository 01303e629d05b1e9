"""QoS profiles of the switchobs topics (docs/reference/topics.md).

* Sensor inputs (``camera/pose``, ``target/pose``): ``qos_profile_sensor_data`` (best effort,
  volatile; a best-effort subscriber also accepts reliable publishers). Publishers keep the
  profile's depth 5; the estimator's subscriptions keep the last ``SENSOR_SUB_DEPTH`` = 50
  samples, so a scheduling hiccup of the node (garbage collection, a busy core) delays
  samples instead of dropping them (measured: with depth 5 a loaded 2-core machine lost
  about 2-5 % of the samples at 300 samples/s).
* ``camera/active_channel``: **reliable**, volatile, keep last 10. A lost channel message would
  attribute target poses to the wrong channel until the next switch, so it must not be lost.
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
CHANNEL_SUB = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE, history=QoSHistoryPolicy.KEEP_LAST)
CHANNEL_PUB = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)
OUTPUT = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
TRUTH = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE)
#: /clock as rclpy's TimeSource subscribes to it (reliable would also match; keep it simple).
CLOCK = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.BEST_EFFORT)
