"""Fast CDR for the few fixed-layout messages the offline estimator reads and writes.

``rclpy.serialization`` builds a full Python message object per call (about 20-50 us for a
PoseStamped or an Odometry, mostly nested ``__init__``); over a bag that is most of the offline
estimator's time. Here:

* :func:`decode_pose` reads a little-endian CDR ``geometry_msgs/PoseStamped`` into a light
  object with the same attribute paths (``header.stamp.sec``, ``pose.position.x``, ...), which
  is all that :func:`msg_bridge.check_pose` and :func:`msg_bridge.pose_to_xy` read. Anything
  it does not recognise exactly (big-endian, a length that does not add up) goes to rclpy. The
  estimator itself reads its inputs' bytes with :class:`msg_bridge.parse.RawReader` (no object
  at all); this one serves scripts that want message-like objects (bench/bench_replay.py).
* :class:`Template` serialises a message once with rclpy and then only patches the bytes of
  the fields that change (the stamp and some float64s) with ``struct.pack_into``.

Both are checked against rclpy byte for byte / field for field in test/ros/test_bag_tools.py.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["Template", "decode_pose", "decode_uint8", "header_stamp"]

_HDR_LE = (b"\x00\x01", b"\x00\x03")     # CDR_LE, PL_CDR_LE (encapsulation id, big-endian u16)
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_SEVEN = struct.Struct("<7d")


class _Obj:
    """A plain attribute holder (duck-typed message part)."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def decode_pose(data: bytes, fallback: Callable[[bytes], object]):
    """A PoseStamped view of the CDR ``data``; ``fallback(data)`` where the layout is not the plain one."""
    if len(data) < 16 or data[:2] not in _HDR_LE:
        return fallback(data)
    sec, nsec = _STAMP.unpack_from(data, 4)
    (n,) = _U32.unpack_from(data, 12)            # frame_id length, including the terminating NUL
    end = 16 + n
    off = end + (-(end - 4)) % 8                  # doubles are 8-aligned relative to the payload start
    if n == 0 or off + 56 != len(data) or data[end - 1] != 0:
        return fallback(data)
    try:
        frame = data[16:end - 1].decode()
    except UnicodeDecodeError:
        return fallback(data)
    px, py, pz, qx, qy, qz, qw = _SEVEN.unpack_from(data, off)
    return _Obj(header=_Obj(stamp=_Obj(sec=sec, nanosec=nsec), frame_id=frame),
                pose=_Obj(position=_Obj(x=px, y=py, z=pz), orientation=_Obj(x=qx, y=qy, z=qz, w=qw)))


def header_stamp(data: bytes) -> tuple[int, int] | None:
    """``(sec, nanosec)`` of the ``std_msgs/Header`` that starts the little-endian CDR ``data`` of a
    stamped message (PoseStamped, PointStamped, Odometry, ...); None for another encoding."""
    if len(data) < 12 or data[:2] not in _HDR_LE:
        return None
    return _STAMP.unpack_from(data, 4)


def decode_uint8(data: bytes, fallback: Callable[[bytes], object]):
    """A std_msgs/UInt8 view of the CDR ``data``."""
    if len(data) >= 5 and data[:2] in _HDR_LE:
        return _Obj(data=data[4])
    return fallback(data)


class Template:
    """A message serialised once; :meth:`bytes` patches the stamp and float64 fields.

    ``Template(msg, stamp=("header", "stamp"), doubles=[("pose", "pose", "position", "x"), ...])``
    or, for a sequence of float64 (a Float64MultiArray's ``data`` of fixed length),
    ``Template(msg, array=("data",))`` (the values as a sequence, or a float64 array written in one
    copy); ``arrays=[("x",), ("covariance",)]``: several float64 sequences of fixed lengths, each
    given as a float64 array (``bytes(arrays=(x, P))``). Offsets are found by serialising sentinel values.
    """

    def __init__(self, msg, *, stamp: Sequence[str] | None = None, doubles: Sequence[Sequence[str]] = (),
                 array: Sequence[str] | None = None, arrays: Sequence[Sequence[str]] = ()):
        from rclpy.serialization import serialize_message

        from msg_bridge.cdr_padding import zero_padding

        def setattr_path(obj, path, value):
            for p in path[:-1]:
                obj = getattr(obj, p)
            setattr(obj, path[-1], value)

        self.stamp_off = self.array_off = None
        self.double_offs: list[int] = []
        sentinels = [1.0e-300 * (k + 1.2345) for k in range(len(doubles))]
        for path, v in zip(doubles, sentinels):
            setattr_path(msg, path, v)
        if stamp is not None:
            obj = msg
            for p in stamp:
                obj = getattr(obj, p)
            obj.sec, obj.nanosec = 0x5A3C5A3C, 0x3C5A3C5A
        if array is not None:
            obj = msg
            for p in array[:-1]:
                obj = getattr(obj, p)
            n = len(getattr(obj, array[-1]))
            setattr(obj, array[-1], [2.0e-300 * (k + 1.5) for k in range(n)])
            self.array_n = n
            self._arr = struct.Struct(f"<{n}d")
        sizes = []
        for j, path in enumerate(arrays):
            obj = msg
            for p in path[:-1]:
                obj = getattr(obj, p)
            sizes.append(len(getattr(obj, path[-1])))
            setattr(obj, path[-1], [(4.0 + j) * 1.0e-300 * (k + 1.5) for k in range(sizes[-1])])
        blob = bytes(zero_padding(msg, serialize_message(msg)))      # no heap bytes in the padding
        if stamp is not None:
            self.stamp_off = _unique(blob, _STAMP.pack(0x5A3C5A3C, 0x3C5A3C5A), "stamp")
        for v in sentinels:
            self.double_offs.append(_unique(blob, struct.pack("<d", v), "double"))
        if array is not None:
            self.array_off = _unique(blob, struct.pack("<d", 2.0e-300 * 1.5), "array")
        self.arrays = [(_unique(blob, struct.pack("<d", (4.0 + j) * 1.0e-300 * 1.5), "array") if n else 0, n)
                       for j, n in enumerate(sizes)]
        self.base = bytearray(blob)

    def bytes(self, stamp_ns: int | None = None, doubles: Sequence[float] = (), array: Sequence[float] = (),
              arrays: Sequence[np.ndarray] = ()) -> bytes:
        b = self.base
        if len(arrays) != len(self.arrays):
            raise ValueError(f"template: {len(arrays)} arrays for {len(self.arrays)}")
        _put_arrays(b, self.arrays, arrays)
        if stamp_ns is not None:
            _STAMP.pack_into(b, self.stamp_off, *divmod(int(stamp_ns), 1_000_000_000))
        for off, v in zip(self.double_offs, doubles):
            struct.pack_into("<d", b, off, v)
        if self.array_off is not None:
            if isinstance(array, np.ndarray):       # the doubles' bytes at once (a covariance: 17 424 of them)
                _put_arrays(b, ((self.array_off, self.array_n),), (array,))
            else:
                self._arr.pack_into(b, self.array_off, *array)
        return bytes(b)

    def pieces(self, stamp_ns: int | None = None, arrays: Sequence[np.ndarray] = ()) -> tuple:
        """The bytes of :meth:`bytes` ``(stamp_ns, arrays=arrays)`` as pieces to be written in turn, the
        last array not copied: ``(before, its doubles, after)`` (``after`` omitted when empty), the
        middle a byte view of that array (float64, C order) valid while it is unchanged. Only for a
        template whose last array is the last of them in the layout."""
        if not self.arrays or len(arrays) != len(self.arrays):
            raise ValueError(f"template: {len(arrays)} arrays for {len(self.arrays)}")
        off, n = self.arrays[-1]
        if any(o > off for o, _ in self.arrays[:-1]):
            raise ValueError("template: the last array is not the last in the layout")
        last = _doubles(arrays[-1], n)
        b = self.base
        _put_arrays(b, self.arrays[:-1], arrays[:-1])
        if stamp_ns is not None:
            _STAMP.pack_into(b, self.stamp_off, *divmod(int(stamp_ns), 1_000_000_000))
        view, mv = memoryview(last).cast("B"), memoryview(b)
        end = off + 8 * n
        return (bytes(mv[:off]), view) if end == len(b) else (bytes(mv[:off]), view, bytes(mv[end:]))


def _doubles(values: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    """``values`` as n little-endian doubles in C order (a view where they are already)."""
    a = np.ascontiguousarray(values, dtype="<f8").reshape(-1)
    if a.size != n:
        raise ValueError(f"template: {a.size} values for an array of {n}")
    return a


def _put_arrays(b: bytearray, slots: Sequence[tuple[int, int]], arrays: Sequence) -> None:
    """Each array's doubles written at its slot ``(offset, length)`` of ``b``."""
    for (off, n), values in zip(slots, arrays):
        b[off:off + 8 * n] = _doubles(values, n).tobytes()


def _unique(blob: bytes, pattern: bytes, what: str) -> int:
    i = blob.find(pattern)
    if i < 0 or blob.find(pattern, i + 1) >= 0:
        raise ValueError(f"template: the {what} sentinel is not found exactly once")
    return i
