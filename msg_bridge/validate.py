"""Validation of incoming messages: a :class:`Rejection` with a :class:`Reason` code, or None.

The node counts rejections by reason (diagnostics) and keeps running; see the failure
catalogue, docs/failures.md. The checks are pure functions of the message and what the caller knows (the
last accepted stamp on the same topic, the node's clock).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from std_msgs.msg import UInt8

from switchobs_core.exceptions import SwitchobsError

from .stamps import time_ns, valid_time

__all__ = ["BridgeError", "SpecError", "Reason", "Rejection", "channel_value", "check_after_switch", "check_channel",
           "check_pose", "check_stamp", "check_time", "check_values", "read_channel"]


class Reason(enum.Enum):
    """Why an incoming message was rejected (the value is the diagnostics key)."""

    NON_FINITE = "non_finite"            # NaN or inf in a pose field
    TOO_LARGE = "too_large"              # |value| above the configured bound (e.g. 1e300)
    WRONG_FRAME = "wrong_frame"          # header.frame_id is not the expected frame
    ZERO_STAMP = "zero_stamp"            # header.stamp == 0 (unset)
    BAD_STAMP = "bad_stamp"              # negative seconds or nanosec >= 1e9 (not a valid time)
    OLD_STAMP = "old_stamp"              # older than the last accepted stamp on this topic
    DUPLICATE_STAMP = "duplicate_stamp"  # equal to the last accepted stamp on this topic
    FUTURE_STAMP = "future_stamp"        # ahead of the node clock by more than the tolerance
    BAD_CHANNEL = "bad_channel"          # active channel outside 1..N
    NO_CHANNEL = "no_channel"            # a pose before any active-channel message
    STALE_AFTER_SWITCH = "stale_after_switch"  # target pose taken before the last switch
    INTERNAL_ERROR = "internal_error"    # an exception while handling the message (counted, node runs on)
    BAD_LAYOUT = "bad_layout"            # a labelled array not ours / naming no state entry; bytes not the type
    AMBIGUOUS_CHANNEL = "ambiguous_channel"  # the sample's channel was not certain (never guessed)
    INCONSISTENT = "inconsistent"        # the innovation exceeds what the published bound allows
    OUTLIER = "outlier"                  # the normalised innovation exceeds the chi-square gate


@dataclass(frozen=True)
class Rejection:
    """A rejected message: the reason code, the offending field and a one-line detail."""

    reason: Reason
    field: str
    detail: str

    def __str__(self) -> str:
        return f"{self.reason.value}: {self.field}: {self.detail}"


class BridgeError(SwitchobsError, ValueError):
    """A message or array that msg_bridge cannot convert: a :class:`Rejection` (``rejection``,
    for callers that prefer an exception to a return value) or a layout that is not ours."""

    def __init__(self, what: Rejection | str):
        super().__init__(str(what))
        self.rejection = what if isinstance(what, Rejection) else None


def check_stamp(
    stamp_ns: int,
    *,
    last_ns: int | None = None,
    now_ns: int | None = None,
    future_tolerance_ns: int = 500_000_000,
    field: str = "header.stamp",
) -> Rejection | None:
    """Zero, older-than-last, duplicate and future stamps.

    ``now_ns`` None or 0 (a sim-time clock that has not ticked yet) skips the future check.
    """
    if stamp_ns == 0:
        return Rejection(Reason.ZERO_STAMP, field, "stamp is 0 (unset)")
    if stamp_ns < 0:
        return Rejection(Reason.BAD_STAMP, field, f"negative stamp ({stamp_ns} ns)")
    if last_ns is not None:
        if stamp_ns == last_ns:
            return Rejection(Reason.DUPLICATE_STAMP, field, f"same stamp as the last accepted ({stamp_ns} ns)")
        if stamp_ns < last_ns:
            return Rejection(Reason.OLD_STAMP, field,
                             f"{(last_ns - stamp_ns) * 1e-9:.6f} s older than the last accepted")
    if now_ns and stamp_ns > now_ns + future_tolerance_ns:
        return Rejection(Reason.FUTURE_STAMP, field,
                         f"{(stamp_ns - now_ns) * 1e-9:.6f} s ahead of the node clock "
                         f"(tolerance {future_tolerance_ns * 1e-9:g} s)")
    return None


def check_pose(
    msg: Any,
    *,
    frame_id: str | None = None,
    max_abs: float = 1e6,
    last_ns: int | None = None,
    now_ns: int | None = None,
    future_tolerance_ns: int = 500_000_000,
) -> Rejection | None:
    """Every pose field finite, positions within ``max_abs``, the frame, then the stamp.

    ``msg`` is a PoseStamped's :data:`~msg_bridge.parse.Parsed` form ``(sec, nanosec, frame_id,
    values)`` (its serialised bytes read by :class:`~msg_bridge.parse.RawReader`), or a message
    object (rclpy, rosbags, or any with the same attribute paths), parsed into that form first: one
    check for both. ``frame_id`` None or "" accepts any frame.
    """
    if msg.__class__ is not tuple:
        msg = _pose_parser().parse(msg)
        if msg.__class__ is not tuple:      # bytes that are not a PoseStamped: its rejection
            return msg
    sec, nsec, frame, v = msg
    s = v[0] + v[1] + v[2] + v[3] + v[4] + v[5] + v[6]   # finite only if all seven are (else, or on overflow: the loop)
    if not (abs(v[0]) <= max_abs and abs(v[1]) <= max_abs and abs(v[2]) <= max_abs and s - s == 0.0):
        for k in range(7):
            x = v[k]
            if not math.isfinite(x):
                return Rejection(Reason.NON_FINITE, _POSE_FIELDS[k], f"{x}")
            if k < 3 and abs(x) > max_abs:
                return Rejection(Reason.TOO_LARGE, _POSE_FIELDS[k], f"|{x:g}| > {max_abs:g}")
    if frame_id and frame != frame_id:
        return Rejection(Reason.WRONG_FRAME, "header.frame_id", f"'{frame}' (expected '{frame_id}')")
    stamp_ns = time_ns(sec, nsec)
    if stamp_ns is None:
        return check_time(sec, nsec)
    return check_stamp(stamp_ns, last_ns=last_ns, now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)


#: A PoseStamped's float64 fields, in the order of its parsed ``values``.
_POSE_FIELDS = ("pose.position.x", "pose.position.y", "pose.position.z",
                "pose.orientation.x", "pose.orientation.y", "pose.orientation.z", "pose.orientation.w")


@cache
def _pose_parser() -> Any:
    from .parse import Parser  # parse builds on this module's Rejection

    p = Parser("geometry_msgs/msg/PoseStamped", _POSE_FIELDS)
    if p.fields != _POSE_FIELDS or p.index != tuple(range(7)):
        raise AssertionError("PoseStamped's float64 fields are not the seven pose fields")
    return p


def check_time(sec: int, nsec: int) -> Rejection | None:
    """A header stamp's ``sec`` and ``nanosec`` a valid time (:func:`msg_bridge.stamps.valid_time`)."""
    if not valid_time(sec, nsec):
        return Rejection(Reason.BAD_STAMP, "header.stamp",
                         f"sec {sec}, nanosec {nsec} is not a valid time (sec >= 0, nanosec < 1e9)")
    return None


def check_values(y: np.ndarray, fields: Sequence[str], *, max_abs: float = 1e6) -> Rejection | None:
    """Every value of a sample (:meth:`msg_bridge.fields.FieldReader.read`) finite and within
    ``max_abs``; the rejection names the first offending field."""
    a = np.abs(y)
    if a.max(initial=0.0) <= max_abs:         # False for a NaN too
        return None
    k = int(np.argmax(~np.isfinite(y) | (a > max_abs)))
    v = float(y[k])
    if not math.isfinite(v):
        return Rejection(Reason.NON_FINITE, fields[k], f"{v}")
    return Rejection(Reason.TOO_LARGE, fields[k], f"|{v:g}| > {max_abs:g}")


def check_after_switch(stamp_ns: int, switch_ns: int | None, field: str = "header.stamp") -> Rejection | None:
    """A target pose must be newer than the last switch.

    ``switch_ns`` is the newest target pose stamp received before the latest change of the
    active channel (None: no switch yet). ``camera/active_channel`` has no
    stamp, so that is all the node knows of the switching instant: a target pose stamped at or
    before it was taken while the previous channel was active and cannot be attributed.
    """
    if switch_ns is not None and stamp_ns <= switch_ns:
        return Rejection(Reason.STALE_AFTER_SWITCH, field,
                         f"{(switch_ns - stamp_ns) * 1e-9:.6f} s older than the last channel switch "
                         "(taken while the previous channel was active)")
    return None


def channel_value(msg: Any) -> int:
    """The channel of a channel-topic message: ``std_msgs/UInt8`` (``data``) or
    ``switchobs_msgs/ActiveChannel`` (``channel``, with the switching instant in its stamp)."""
    return int(msg.channel) if hasattr(msg, "channel") else int(msg.data)


def check_channel(msg: UInt8, N: int) -> Rejection | None:
    """An active channel must be one of the system's channels 1..N (either channel type,
    :func:`channel_value`)."""
    return read_channel(msg, N)[1]


def read_channel(msg: Any, N: int) -> tuple[int, Rejection | None]:
    """:func:`channel_value` and :func:`check_channel` of a channel-topic message in one read:
    ``(channel, None)``, or ``(channel, why it is refused)``."""
    c = channel_value(msg)
    if not 1 <= c <= N:
        return c, Rejection(Reason.BAD_CHANNEL, "channel" if hasattr(msg, "channel") else "data",
                            f"channel {c} is not in 1..{N}")
    return c, None


class SpecError(SwitchobsError, ValueError):
    """An input specification (topic, message type, fields, rows, channel) that cannot work:
    a configuration error, refused at start-up with one line (what, where, what to do)."""
