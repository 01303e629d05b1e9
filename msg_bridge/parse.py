"""Input messages parsed into one form, from serialised bytes or from a message object.

The estimator checks and reads a stamped input message (:func:`~msg_bridge.validate.check_pose`,
:func:`~msg_bridge.validate.check_values`, :class:`~msg_bridge.frames.FramedFields`) as a
:data:`Parsed` tuple ``(sec, nanosec, frame_id, values)``: the header stamp's two integers as sent,
the header's frame id, and ``values``, every float64 field of the type
(:func:`~msg_bridge.fields.float64_fields`, declaration order) as Python floats.

* :class:`RawReader` reads it straight from the serialised message (``Subscription(raw=True)``,
  a bag record's bytes) with one ``struct`` call for the stamp and the frame's length and one for
  the doubles: no message object is built. It reads the types of :data:`RAW_TYPES`, those whose
  layout after the header's ``frame_id`` is fixed (float64 fields and fixed arrays only), in
  little-endian plain CDR (encapsulation ``0x0001``, as rmw_fastrtps writes it): the 4-byte
  encapsulation header; the body: ``int32 sec``, ``uint32 nanosec``, ``uint32`` length of
  ``frame_id`` (its terminating NUL counted), its UTF-8 bytes and the NUL; padding to a multiple
  of 8 bytes from the body's start; the float64 fields. Anything else (another encapsulation, a
  length that does not add up, a frame id that is not UTF-8 or holds a NUL) is a
  :class:`~msg_bridge.validate.Rejection` with reason ``BAD_LAYOUT``, never an exception.
* :class:`Parser` takes either form: bytes go to the :class:`RawReader` (bytes it refuses to
  rclpy's deserialiser, then read as a message: one rule, rclpy's, decides which bytes are a
  message, live and in a bag, the same bytes a node taking rclpy messages accepts; the raw
  reader only makes the well-formed ones cheap), a message object (rclpy,
  rosbags or any object with the same attribute paths) is read attribute by attribute into the
  same tuple, and a :data:`Parsed` tuple is passed through. The checks then run on one form.

test/bridge/test_parse_raw.py compares the raw reader with ``rclpy.serialization.deserialize_message``
on random messages, bit for bit.
"""

from __future__ import annotations

import struct
from functools import cache
from operator import attrgetter, itemgetter
from typing import Any

import numpy as np

from .fields import LABELLED_ARRAY, canonical_type, compile_parse, float64_fields, message_class
from .validate import Reason, Rejection

__all__ = ["RAW_TYPES", "Parsed", "Parser", "RawReader", "raw_readable"]

#: ``(sec, nanosec, frame_id, values)``: a stamped message's header and every float64 field of its type.
Parsed = tuple[int, int, str, tuple[float, ...]]

#: Types whose layout after the header's ``frame_id`` is fixed: :class:`RawReader` reads them.
RAW_TYPES: tuple[str, ...] = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PointStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/AccelStamped",
)

_CDR_LE = b"\x00\x01"            # encapsulation: plain CDR, little-endian (big-endian u16 id, then options)
_HEAD = struct.Struct("<iII")    # sec, nanosec, frame_id length (NUL included), from byte 4
_BYTES = (bytes, bytearray, memoryview)


def raw_readable(type_name: str) -> bool:
    """Whether :class:`RawReader` reads messages of ``type_name`` (one of :data:`RAW_TYPES`)."""
    return canonical_type(type_name) in RAW_TYPES


@cache
def _tail(type_name: str) -> tuple[int, int]:
    """``(float64 fields, bytes after the frame id's padding)`` of a type of :data:`RAW_TYPES`:
    serialised once with distinct values in its float64 fields, which must be the first doubles
    after the header (ValueError otherwise)."""
    from rclpy.serialization import serialize_message

    fields = float64_fields(type_name)
    msg = message_class(type_name)()
    sentinels = [float.fromhex(f"0x1.{k + 1:04x}5a3c5a3cp-990") for k in range(len(fields))]
    for f, v in zip(fields, sentinels):
        obj, _, leaf = f.rpartition(".")
        setattr(attrgetter(obj)(msg) if obj else msg, leaf, v)
    blob = serialize_message(msg)              # frame_id "": length 1, body 13 bytes, padded to 16
    if blob[:2] != _CDR_LE or len(blob) < 20 + 8 * len(fields):
        raise ValueError(f"{type_name}: not a fixed layout in little-endian CDR")
    if struct.unpack_from(f"<{len(fields)}d", blob, 20) != tuple(sentinels):
        raise ValueError(f"{type_name}: its float64 fields are not the first doubles after the header")
    return len(fields), len(blob) - 20


class RawReader:
    """Reads a :data:`Parsed` tuple from a serialised message of a type of :data:`RAW_TYPES`:
    ``RawReader("geometry_msgs/PoseStamped").parse(data)`` (a :class:`Rejection` for bytes that are
    not such a message; module docstring)."""

    __slots__ = ("type", "_k", "_tail", "_vals")

    def __init__(self, type_name: str):
        self.type = canonical_type(type_name)
        if self.type not in RAW_TYPES:
            raise ValueError(f"{self.type} has no fixed layout after its header: read it as a message")
        self._k, self._tail = _tail(self.type)
        self._vals = struct.Struct(f"<{self._k}d")

    def __repr__(self) -> str:
        return f"RawReader({self.type!r})"

    def parse(self, data: bytes | bytearray | memoryview) -> Parsed | Rejection:
        """``(sec, nanosec, frame_id, values)`` of the serialised message ``data``, or why it is not one."""
        size = len(data)
        if size < 16 or data[:2] != _CDR_LE:
            return _bad(f"{size} bytes, encapsulation {bytes(data[:2]).hex() or 'none'} "
                        "(expected little-endian CDR, 0001)")
        sec, nsec, n = _HEAD.unpack_from(data, 4)
        end = 16 + n
        off = end + (-(end - 4)) % 8             # the doubles: 8-aligned from the body's start (byte 4)
        if n == 0:
            return _bad("a frame id length of 0 (CDR counts the terminating NUL: at least 1)")
        if off + self._tail != size:
            return _bad(f"{size} bytes with a frame id of {n} bytes (expected {off + self._tail})")
        raw = bytes(data[16:end - 1])           # bytes: ``in`` on a memoryview compares items, not bytes
        if data[end - 1] != 0 or b"\x00" in raw:
            return _bad("frame id not terminated by its only NUL")
        try:
            frame = str(raw, "utf-8")
        except UnicodeDecodeError:
            return _bad("frame id is not UTF-8")
        return sec, nsec, frame, self._vals.unpack_from(data, off)


def _bad(detail: str) -> Rejection:
    return Rejection(Reason.BAD_LAYOUT, "cdr", detail)


class Parser:
    """One stamped input type's :data:`Parsed` form from bytes, a message or a parsed tuple, and the
    chosen ``fields`` of it as an array: ``p = Parser(type_name, fields)``; ``p.parse(msg)``;
    ``p.values(parsed[3])``.

    ``fields`` are float64 fields of the type (checked by :class:`~msg_bridge.fields.FieldReader`);
    the labelled ``Float64MultiArray`` has no header and no parser.
    """

    __slots__ = ("type", "fields", "raw", "_get", "_pick", "index")

    def __init__(self, type_name: str, fields: tuple[str, ...]):
        self.type = canonical_type(type_name)
        if self.type == LABELLED_ARRAY:
            raise ValueError("a labelled array has no header: read it with FieldReader")
        self.fields = tuple(fields)
        every = float64_fields(self.type)
        self.index = tuple(every.index(f) for f in self.fields)
        self.raw = RawReader(self.type) if self.type in RAW_TYPES else None
        self._get = compile_parse(every)
        idx = self.index
        self._pick = (lambda v, i=idx[0]: (v[i],)) if len(idx) == 1 else itemgetter(*idx)

    def parse(self, msg: Any) -> Parsed | Rejection:
        """The :data:`Parsed` form of ``msg``: serialised bytes (:class:`RawReader`; a rejection
        for a type without a fixed layout), a message object, or a parsed tuple (returned as it is)."""
        if msg.__class__ is tuple:
            return msg
        if isinstance(msg, _BYTES):
            if self.raw is None:
                return _bad(f"{self.type} is read as a message, not from bytes")
            got = self.raw.parse(msg)
            return got if got.__class__ is tuple else self._by_rclpy(msg, got)
        return self._get(msg)

    def _by_rclpy(self, data: bytes | bytearray | memoryview, rejection: Rejection) -> Parsed | Rejection:
        """Bytes the raw reader refuses, read by rclpy's deserialiser as a subscription of rclpy
        messages reads them (and as ``switchobs_bag estimate`` reads a bag's): another
        encapsulation (a big-endian writer's), a frame id that is not UTF-8 (rclpy replaces the bad
        bytes) or not terminated as the raw reader expects, trailing bytes; then parsed as a
        message. ``rejection`` (the raw reader's) when rclpy cannot read them either, so bytes are
        refused by one rule, rclpy's, whichever path reads them."""
        from rclpy.serialization import deserialize_message
        try:
            msg = deserialize_message(bytes(data), message_class(self.type))
        except Exception:       # any failure of the C deserialiser: not such a message
            return rejection
        return self._get(msg)

    def values(self, every: tuple[float, ...]) -> np.ndarray:
        """The chosen fields of a parsed message's ``values`` (a new float64 array)."""
        return np.array(self._pick(every), dtype=float)
