"""Zeroed alignment padding in a serialised ROS 2 message.

``rclpy.serialization.serialize_message`` (rmw_fastrtps, little-endian CDR) leaves the bytes that
align a field (a 4-byte length after a 1-byte field, an 8-byte double after a string, the end's
padding to 4) as the heap held them: a message serialised once and sent many times (a template,
:class:`msg_bridge.raw.RawMessage`, ``switchobs_ros.bag.cdr.Template``) would carry heap bytes into
every copy, and bags written twice would differ. :func:`zero_padding` walks the message's fields
(their rosidl types, the values read from the message for the lengths) in CDR order, with CDR's
alignment (each primitive on a multiple of its size counted from the byte after the 4-byte
encapsulation header) and zeroes each padding byte and those after the last field; rosbags'
``serialize_cdr`` writes the same bytes (``test_cdr_padding.py``).
"""

from __future__ import annotations

from typing import Any

from rosidl_parser.definition import (
    AbstractSequence,
    AbstractString,
    AbstractWString,
    Array,
    BasicType,
    NamespacedType,
)

__all__ = ["zero_padding"]

#: Bytes of each rosidl basic type in CDR.
_SIZE = {"boolean": 1, "octet": 1, "char": 1, "uint8": 1, "int8": 1, "int16": 2, "uint16": 2, "int32": 4,
         "uint32": 4, "float": 4, "int64": 8, "uint64": 8, "double": 8, "long double": 8}
_ORIGIN = 4         # alignment counts from the end of the encapsulation header


def zero_padding(msg: Any, data: bytes | bytearray) -> bytearray:
    """``data`` (``msg`` serialised, little-endian CDR) with its alignment padding and the bytes after
    the last field zeroed. rmw_fastrtps sizes a message as if an empty sequence of a primitive were
    aligned (it is not written so): up to 7 bytes per such sequence, and 3 of final padding, may
    follow the last field. Raises ValueError for another encoding, a wide string, or bytes whose
    fields do not end there (not ``msg``'s serialisation)."""
    buf = bytearray(data)
    if bytes(buf[:2]) != b"\x00\x01":
        raise ValueError("CDR padding: not little-endian CDR")
    walk = _Walk(buf)
    end = walk.fields(msg, _ORIGIN)
    if not end <= len(buf) < end + 4 + 7 * walk.empty:
        raise ValueError(f"CDR padding: the fields end at {end} of {len(buf)} bytes")
    buf[end:] = bytes(len(buf) - end)
    return buf


class _Walk:
    """The fields of a message in CDR order over its bytes ``buf``, zeroing the padding passed;
    ``empty`` counts the empty sequences of primitives, ``zeroed`` the padding bytes passed."""

    def __init__(self, buf: bytearray) -> None:
        self.buf = buf
        self.empty = 0
        self.zeroed = 0

    def align(self, pos: int, size: int) -> int:
        """``pos`` moved to the next multiple of ``size`` (from the origin), the bytes passed zeroed."""
        new = pos + (-(pos - _ORIGIN)) % size
        if new > pos:
            self.buf[pos:new] = bytes(new - pos)
            self.zeroed += new - pos
        return new

    def fields(self, msg: Any, pos: int) -> int:
        names = _names(type(msg))
        if not names:       # a message without fields carries rosidl's hidden uint8 (one byte)
            return pos + 1
        for name, t in zip(names, type(msg).SLOT_TYPES):
            pos = self.value(getattr(msg, name), t, pos)
        return pos

    def count(self, pos: int) -> tuple[int, int]:
        """The uint32 at ``pos`` (aligned first) and the position after it."""
        pos = self.align(pos, 4)
        if pos + 4 > len(self.buf):
            raise ValueError("CDR padding: a length beyond the data")
        return int.from_bytes(self.buf[pos:pos + 4], "little"), pos + 4

    def value(self, v: Any, t: Any, pos: int) -> int:
        if isinstance(t, BasicType):
            size = _SIZE[t.typename]
            return self.align(pos, size) + size
        if isinstance(t, AbstractWString):
            raise ValueError("CDR padding: wide strings are not walked")
        if isinstance(t, AbstractString):
            n, pos = self.count(pos)
            return pos + n
        if isinstance(t, NamespacedType):
            return self.fields(v, pos)
        if isinstance(t, AbstractSequence):
            n, pos = self.count(pos)
        elif isinstance(t, Array):
            n = t.size
        else:
            raise ValueError(f"CDR padding: a field of type {type(t).__name__}")
        et = t.value_type
        if isinstance(et, BasicType):
            if n == 0:          # not aligned (rmw_fastrtps writes nothing)
                self.empty += 1
                return pos
            size = _SIZE[et.typename]
            return self.align(pos, size) + size * n
        for k, item in enumerate(v):
            start, zeroed = pos, self.zeroed
            pos = self.value(item, et, pos)
            if pos > start and self.zeroed == zeroed and (pos - start) % 8 == 0 and isinstance(et, NamespacedType) \
                    and _fixed(item):
                # an item of one size that ended on the 8-byte phase it began on, with no padding:
                # every item after it lies the same way, without padding (the points of a line strip)
                return pos + (len(v) - k - 1) * (pos - start)
        return pos


_NAMES: dict[type, tuple[str, ...]] = {}
_FIXED: dict[type, bool] = {}


def _names(cls: type) -> tuple[str, ...]:
    """A message class's field names, in order (rosidl's ``get_fields_and_field_types``, read once)."""
    got = _NAMES.get(cls)
    if got is None:
        got = _NAMES[cls] = tuple(cls.get_fields_and_field_types())
    return got


def _fixed(msg: Any) -> bool:
    """Whether every message of ``msg``'s type has one size: its fields primitives, fixed arrays of
    primitives, or messages of that kind (no string, no sequence)."""
    cls = type(msg)
    got = _FIXED.get(cls)
    if got is None:
        got = True
        for name, t in zip(_names(cls), cls.SLOT_TYPES):
            if isinstance(t, BasicType) or (isinstance(t, Array) and isinstance(t.value_type, BasicType)):
                continue
            if not (isinstance(t, NamespacedType) and _fixed(getattr(msg, name))):
                got = False
                break
        _FIXED[cls] = got
    return got
