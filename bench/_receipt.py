"""Shared by the live benchmarks' receivers: when a message reached the middleware, not when this
process's Python took it.

rclpy's ``MessageInfo`` carries ``received_timestamp``: Fast DDS stamps a sample when its reader
receives it (rmw_fastrtps: ``SampleInfo.reception_timestamp``, taken on the middleware's receive
thread), on the system clock, the clock of ``time.time_ns()`` and of the ticks' stamps
(``bench/receipt_clock.py`` checks both; rclpy 7.1.5, rmw_fastrtps 8.4.3, Fast DDS 2.14). A
receiver that keeps this time measures the node and the transport; its own queue (the messages
it takes before the answer, the executor's work, the interpreter) stays out. ``source_timestamp``
is the writer's clock when it published (the same system clock on one machine). The Python
arrival (``time.time_ns()`` in the callback) is kept as well, for comparison.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from rclpy.qos import QoSProfile, QoSReliabilityPolicy

#: The receivers' subscriptions: reliable, deep enough that a receiver which falls behind loses
#: nothing from its own history (a keep-last reader overwrites its oldest unread sample).
RECEIVE = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE)
#: A witness of a sensor-data topic (best effort, as its writer), as deep.
WITNESS = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.BEST_EFFORT)

#: The largest (Python arrival - DDS reception) median accepted as "the same clock" (ns): the two
#: clocks of a machine differ by decades (system: since 1970; steady: since boot).
SAME_CLOCK_NS = 1_000_000_000


class Receipts:
    """A raw subscription callback taking ``MessageInfo``: keeps every serialised message with its
    DDS reception time, its writer's source time and its Python arrival time (ns); the messages
    are decoded after the run (:meth:`times`)."""

    def __init__(self) -> None:
        self.rows: list[tuple[bytes, int, int, int]] = []

    def __call__(self, raw: bytes, info) -> None:
        self.rows.append((raw, info["received_timestamp"], info["source_timestamp"], time.time_ns()))

    def __len__(self) -> int:
        return len(self.rows)

    def times(self, stamp_of: Callable[[bytes], int]) -> dict[int, tuple[int, int, int]]:
        """``{stamp: (DDS reception, source, Python arrival)}``, the first message of each stamp;
        raises ``RuntimeError`` if the reception times are not on this process's system clock."""
        check_system_clock(np.array([r[1:] for r in self.rows], dtype=np.int64).reshape(-1, 3))
        out: dict[int, tuple[int, int, int]] = {}
        for raw, dds, src, py in self.rows:
            out.setdefault(stamp_of(raw), (dds, src, py))
        return out


def check_system_clock(t: np.ndarray) -> float:
    """The median of (Python arrival - DDS reception) over rows ``(dds, source, python)`` in ns;
    ``RuntimeError`` unless it lies in [0, 1 s) (reception before arrival, same clock) or a
    reception time is 0 (not filled)."""
    if not t.size:
        return float("nan")
    if (t[:, 0] == 0).any():
        raise RuntimeError("MessageInfo received_timestamp is 0: this middleware does not fill it")
    d = float(np.median(t[:, 2] - t[:, 0]))
    if not 0 <= d < SAME_CLOCK_NS:
        raise RuntimeError(f"received_timestamp is {d * 1e-9:.3g} s from time.time_ns(): not the system clock")
    return d


def pose_stamp(raw: bytes) -> int:
    """The header stamp (ns) of a serialised ``geometry_msgs/PoseStamped``."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import deserialize_message
    s = deserialize_message(raw, PoseStamped).header.stamp
    return s.sec * 1_000_000_000 + s.nanosec


def labelled_stamp(raw: bytes) -> int:
    """The stamp (ns) of a serialised labelled ``std_msgs/Float64MultiArray`` (``msg_bridge``'s)."""
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray

    import msg_bridge as mb
    return mb.unpack_labelled(deserialize_message(raw, Float64MultiArray)).stamp_ns
