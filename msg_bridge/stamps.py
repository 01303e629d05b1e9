"""Header stamps <-> integer nanoseconds (exact; floats only at the very end)."""

from __future__ import annotations

from builtin_interfaces.msg import Time

__all__ = ["ns_to_stamp", "stamp_to_ns", "stamp_to_sec"]

_NS = 1_000_000_000


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds since the clock's epoch."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds -> ``builtin_interfaces/Time`` (``ns >= 0``)."""
    ns = int(ns)
    if ns < 0:
        raise ValueError(f"a stamp must be >= 0 ns; got {ns}")
    return Time(sec=ns // _NS, nanosec=ns % _NS)


def stamp_to_sec(stamp: Time) -> float:
    """``builtin_interfaces/Time`` -> float seconds (for display; keep ns for arithmetic)."""
    return stamp.sec + stamp.nanosec * 1e-9
