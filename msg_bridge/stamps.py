"""Header stamps <-> integer nanoseconds (exact; floats only at the very end).

This module owns the stamp's constant (:data:`NS_PER_S`) and the rule "a header stamp is a valid
time" (:func:`time_ns` for a header's two integers, :func:`float_time_ns` for the two doubles a
labelled array carries): every layer that turns a ``(sec, nanosec)`` pair into nanoseconds calls
them, each keeping its own rejection (a :class:`~msg_bridge.validate.Rejection`, a
:class:`~msg_bridge.validate.BridgeError`, or no evidence).
"""

from __future__ import annotations

from builtin_interfaces.msg import Time

__all__ = ["MAX_SEC", "NS_PER_S", "float_time_ns", "ns_to_stamp", "stamp_to_ns", "stamp_to_sec", "time_ns",
           "valid_time"]

#: Nanoseconds per second: ``builtin_interfaces/Time`` is ``sec * NS_PER_S + nanosec`` ns.
NS_PER_S = 1_000_000_000
#: The largest ``sec`` a header stamp holds (``builtin_interfaces/Time.sec`` is an int32): a labelled
#: array's stamp above it could not be published in a header (it would wrap), and its nanoseconds
#: stay far inside an int64.
MAX_SEC = 2**31 - 1


def valid_time(sec: int, nsec: int) -> bool:
    """Whether a header stamp's two integers are a valid time: ``sec >= 0`` and ``0 <= nsec < NS_PER_S``
    (``int32 sec``, ``uint32 nanosec``: the types make them integers, so they are not checked here)."""
    return sec >= 0 and 0 <= nsec < NS_PER_S


def time_ns(sec: int, nsec: int) -> int | None:
    """``sec * NS_PER_S + nsec`` of a header stamp's two integers as a Python int (numpy integers too:
    no int32 wrap), or None unless :func:`valid_time`. Its comparisons are written out here: this runs
    once per message received."""
    if sec >= 0 and 0 <= nsec < NS_PER_S:
        return int(sec) * NS_PER_S + int(nsec)
    return None


def float_time_ns(sec: float, nsec: float) -> int | None:
    """:func:`time_ns` of the two doubles a labelled array carries as its stamp
    (:mod:`msg_bridge.convert`), or None unless both are finite whole numbers, a valid time, and
    ``sec <= MAX_SEC`` (what a header can carry)."""
    sec, nsec = float(sec), float(nsec)
    # time_ns's comparisons on the doubles (false for NaN), written out: this runs once per labelled array read
    if 0.0 <= sec <= MAX_SEC and 0.0 <= nsec < NS_PER_S and sec.is_integer() and nsec.is_integer():
        return int(sec) * NS_PER_S + int(nsec)
    return None


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` -> integer nanoseconds since the clock's epoch."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds -> ``builtin_interfaces/Time`` (``ns >= 0``)."""
    ns = int(ns)
    if ns < 0:
        raise ValueError(f"a stamp must be >= 0 ns; got {ns}")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def stamp_to_sec(stamp: Time) -> float:
    """``builtin_interfaces/Time`` -> float seconds (for display; keep ns for arithmetic)."""
    return stamp.sec + stamp.nanosec * 1e-9
