"""The channel topic's message type: ``switchobs_msgs/ActiveChannel`` (stamped with the switching
instant) or ``std_msgs/UInt8`` (parameter ``channel_type``; ``auto``: the type the topic's
publishers offer in the ROS graph, ActiveChannel when one does, UInt8 while none is known: the node
asks again until a channel message has arrived, so a publisher that starts later is followed)."""

from __future__ import annotations

from typing import Any

from std_msgs.msg import UInt8
from switchobs_msgs.msg import ActiveChannel

from msg_bridge.typed import ACTIVE_CHANNEL

__all__ = ["CHANNEL_MSG", "channel_type"]

UINT8 = "std_msgs/msg/UInt8"
#: The message class of each channel type.
CHANNEL_MSG = {ACTIVE_CHANNEL: ActiveChannel, UINT8: UInt8}


def channel_type(node: Any, topic: str, kind: str) -> str:
    """The channel type to subscribe ``topic`` (relative) with on ``node`` for parameter value
    ``kind`` (module docstring)."""
    if kind != "auto":
        return kind
    offered = {i.topic_type for i in node.get_publishers_info_by_topic(node.resolve_topic_name(topic))}
    return next((k for k in (ACTIVE_CHANNEL, UINT8) if k in offered), UINT8)
