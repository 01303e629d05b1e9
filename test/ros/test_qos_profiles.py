"""The channel publisher's QoS keeps one reorder window of messages at its rate (switchobs_ros.qos):
a reliable writer repairs a lost message only from its history, and a repair later than the window
is of no use (bench/bench_netns.py measures 1, 5 and 100 messages under loss)."""

from __future__ import annotations

import math

import pytest
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSReliabilityPolicy

from switchobs_ros import qos


@pytest.mark.parametrize("rate", [0.0, -1.0, math.nan, 1.0, 20.0, 100.0, 101.0, 1000.0])
def test_channel_history_is_one_reorder_window_at_the_rate(rate):
    p = qos.channel_pub(rate)
    want = max(1, math.ceil(rate * qos.CHANNEL_WINDOW_S)) if math.isfinite(rate) and rate > 0 else 1
    assert p.depth == want and p.depth >= 1
    assert p.history == QoSHistoryPolicy.KEEP_LAST
    assert p.reliability == QoSReliabilityPolicy.RELIABLE and p.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL


def test_the_estimators_channel_subscription_matches_the_publisher():
    """Reliable on both sides (a reliable reader does not match a best-effort writer); a volatile reader
    matches a transient-local writer."""
    assert qos.CHANNEL_SUB.reliability == qos.channel_pub(100.0).reliability == QoSReliabilityPolicy.RELIABLE
    assert qos.CHANNEL_SUB.durability == QoSDurabilityPolicy.VOLATILE
    assert qos.channel_pub(100.0).depth == 5 and qos.CHANNEL_WINDOW_S == 0.05
