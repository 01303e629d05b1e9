"""Outputs published as serialised bytes: a message of fixed layout serialised once, its numeric
fields written through numpy views onto those bytes.

``Publisher.publish(msg)`` converts a Python message to its C form field by field (a property
call per field, every string and array copied) and then serialises it; for one
``nav_msgs/Odometry`` that is about 30 us of the 45 us a publish costs, and for ``~/covariance``
the 440 KB label string and the n^2 doubles are converted at every publish. ``publish(bytes)``
hands serialised bytes to the middleware as they are (rmw ``publish_serialized_message``). The
writers here keep the serialised message of :mod:`msg_bridge.convert` /
:mod:`msg_bridge.typed` and rewrite only the numbers that change, in place, with numpy
assignments (no per-element Python); each publish then costs one ``bytes`` copy of the buffer.
The bytes are those ``rclpy.serialization.serialize_message`` gives for the message the
corresponding writer builds, the CDR alignment padding zeroed (:mod:`msg_bridge.cdr_padding`;
test/bridge/test_raw.py compares them byte for byte).

* :class:`RawMessage`: the serialised message and views of its stamp and float64 fields, found
  by serialising sentinel values (little-endian CDR, as rmw_fastrtps writes it on x86 and ARM).
* :class:`RawLabelledArrayWriter`: ``~/state``, ``~/envelope``, ``~/covariance``
  (:func:`~msg_bridge.convert.labelled_array`).
* :class:`RawOdometryBatch`: every body's ``nav_msgs/Odometry``
  (:func:`~msg_bridge.convert.body_odometry`), covariance blocks from ``P``, in one buffer.

A message whose size changes from one publish to the next (a string that changes, a sequence
that is sometimes empty) has no fixed layout: those stay Python messages.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .cdr_padding import zero_padding
from .convert import STAMP_PAD, Body, body_odometry, labelled_array
from .stamps import NS_PER_S

__all__ = ["DTYPES", "RawLabelledArrayWriter", "RawMessage", "RawOdometryBatch"]

#: numpy dtypes of the fields a :class:`RawMessage` can locate (little-endian CDR).
DTYPES = ("<f8", "<f4", "<i4")


def _resolve(msg: Any, path: str) -> tuple[Any, str]:
    """The object that holds the last field of the dotted ``path`` (``markers[3].points[0].x``:
    indices allowed), and that field's name."""
    *head, last = path.split(".")
    for p in head:
        name, _, index = p.partition("[")
        msg = getattr(msg, name)
        if index:
            msg = msg[int(index.rstrip("]"))]
    return msg, last


def _sentinel(dtype: str, k: int, salt: int) -> tuple[float | int, bytes]:
    """The ``k``-th sentinel value of a field of ``dtype`` (``salt`` 0 to :data:`SALTS` - 1: distinct
    sets) and its bytes. Sentinels of one dtype and salt share constant bits (a float64's low 32
    bits, a 4-byte value's high 16), which :func:`_find_each` looks for first; every salt changes
    those bits."""
    if dtype == "<f8":
        v = float.fromhex(f"0x1.{k + 1:04x}5a3c5a3c{5 + salt}p-990")
        return v, struct.pack("<d", v)
    if dtype == "<f4":
        v = struct.unpack("<f", struct.pack("<I", 0x0D5A0000 + (salt << 24) + k))[0]
        return v, struct.pack("<f", v)
    v = 0x5A3C0000 - (salt << 24) + k
    return v, struct.pack("<i", v)


#: The sentinel sets :class:`RawMessage` may serialise with (two always; more while a field is
#: still found at several offsets).
SALTS = 4


class RawMessage:
    """``msg`` serialised once, with writable numpy views of chosen numeric fields.

    ``RawMessage(msg, stamp="header.stamp", doubles={"p": ("pose.pose.position.x", 3)},
    fields={"a": ("action", "<i4", 1)})``: ``fields`` maps a name to (the dotted path of a field,
    its dtype in :data:`DTYPES`, the number of consecutive values of that dtype from it: 1 for a
    scalar, more for consecutive scalars such as ``position.x, .y, .z`` or an array);
    ``doubles`` is the same for float64 fields, ``(path, count)``; ``stamp`` the path of a
    ``builtin_interfaces/Time`` (its view: name ``"stamp"``, ``sec`` and ``nanosec`` as int32).
    :attr:`f` holds the views by name, :attr:`offsets` their byte offsets; :meth:`stamp` writes
    the stamp; :meth:`bytes` is the message to publish. ``msg`` itself is left as it was.

    Offsets are found by serialising the message with distinct sets of sentinel values in the
    fields: a field is at the offsets where every set's sentinel is found, and must end at exactly
    one. rclpy leaves the CDR padding bytes as memory held them, which may be a sentinel serialised
    earlier in the process, at any offset (measured: a marker array's stamp sentinel found twice
    after a few dozen writers had been built): the message kept has them zeroed
    (:func:`~msg_bridge.cdr_padding.zero_padding`), the serialisations searched (one walk of the
    fields fewer each) do not. Two sets always, up to :data:`SALTS` while a field is still found at
    more than one offset. Raises ValueError when a
    field cannot be located that way or the encoding is not little-endian CDR.
    """

    def __init__(self, msg: Any, stamp: str | None = None, doubles: Mapping[str, tuple[str, int]] | None = None,
                 fields: Mapping[str, tuple[str, str, int]] | None = None):
        from rclpy.serialization import serialize_message

        spec = {name: (path, "<f8", count) for name, (path, count) in (doubles or {}).items()}
        spec.update(fields or {})
        if stamp is not None:
            spec["stamp"] = (f"{stamp}.sec", "<i4", 2)
        # its alignment padding zeroed (rclpy leaves heap bytes there); ValueError but for little-endian CDR
        base = bytes(zero_padding(msg, serialize_message(msg)))
        at: dict[str, set[int]] = {}
        for salt in range(SALTS):
            marked, patterns = self._marked(msg, spec, salt, serialize_message)
            if len(marked) != len(base):
                raise ValueError("raw message: the layout changed with the field values")
            seen = _find_each(marked, patterns)
            at = seen if not at else {name: at[name] & seen[name] for name in spec}
            if salt >= 1 and all(len(o) == 1 for o in at.values()):
                break
        for name, o in at.items():
            if len(o) != 1:
                raise ValueError(f"raw message: the sentinels of {name} are found at {len(o)} offsets "
                                 "in the serialised bytes")
        self._buf = self.buffer = bytearray(base)     # the serialised message, written through the views
        self.offsets: dict[str, int] = {name: next(iter(o)) for name, o in at.items()}
        self.f: dict[str, np.ndarray] = {}
        for name, (_, dtype, count) in spec.items():
            off = self.offsets[name]
            if off + np.dtype(dtype).itemsize * count > len(base):
                raise ValueError(f"raw message: {name} runs past the end of the message")
            self.f[name] = np.frombuffer(self._buf, dtype=dtype, count=count, offset=off)
        self._stamp = self.f.get("stamp")

    @staticmethod
    def _marked(msg: Any, spec: dict, salt: int, serialize) -> tuple[bytes, dict[str, bytes]]:
        """``msg`` serialised with the sentinels of ``salt`` in its fields (``msg`` restored after)."""
        undo = []                               # restores msg, last change first
        patterns = {}
        counters = dict.fromkeys(DTYPES, 0)
        try:
            for name, (path, dtype, _) in spec.items():
                obj, field = _resolve(msg, path)
                old = getattr(obj, field)
                v, patterns[name] = _sentinel(dtype, counters[dtype], salt)
                counters[dtype] += 1
                if isinstance(old, (float, int)):     # a scalar (the first of ``count`` consecutive ones)
                    undo.append(lambda o=obj, f=field, val=old: setattr(o, f, val))
                    setattr(obj, field, v)
                else:                           # an array: its first element (the rest follow it)
                    undo.append(lambda a=old, val=old[0]: a.__setitem__(0, val))
                    old[0] = v
            return serialize(msg), patterns
        finally:
            for restore in reversed(undo):
                restore()

    def stamp(self, stamp_ns: int) -> None:
        """Write the header stamp (integer nanoseconds)."""
        self._stamp[0], self._stamp[1] = divmod(int(stamp_ns), NS_PER_S)

    def bytes(self) -> bytes:
        """The serialised message as it is now (a copy: the caller may publish it while the views are rewritten)."""
        return bytes(self._buf)


def _find_each(blob: bytes, patterns: Mapping[str, bytes]) -> dict[str, set[int]]:
    """The offsets of each sentinel pattern of :func:`_sentinel` in ``blob``, by name. One
    vectorised pass per size and alignment picks the words that carry a sentinel's constant bits,
    then those few are looked up."""
    at: dict[bytes, list[int]] = {p: [] for p in patterns.values()}
    for size in sorted({len(p) for p in patterns.values()}):
        kind = f"<u{size}"
        mask = 0xFFFFFFFF if size == 8 else 0xFFFF0000
        marks = np.array(sorted({int.from_bytes(p, "little") & mask for p in patterns.values() if len(p) == size}),
                         dtype=kind)
        for a in range(size):
            words = np.frombuffer(blob, dtype=kind, offset=a, count=(len(blob) - a) // size)
            hit = np.zeros(words.size, dtype=bool)
            low = words & np.array(mask, dtype=kind)
            for m in marks:
                hit |= low == m
            for i in np.flatnonzero(hit):
                p = bytes(blob[a + size * int(i):a + size * (int(i) + 1)])
                if p in at:
                    at[p].append(a + size * int(i))
    return {name: set(at[p]) for name, p in patterns.items()}


class RawLabelledArrayWriter:
    """:func:`~msg_bridge.convert.labelled_array` as serialised bytes: ``w.msg(values, stamp_ns)``
    (``values`` a float64 array of the labels' length, written in one copy); ``w.write(values,
    stamp_ns)`` the same message in the writer's own buffer, not copied (valid until the next write:
    for a publisher that copies it at once, as rcl's ``publish_raw``; ``~/covariance`` is 0.55 MB at
    n = 132)."""

    def __init__(self, labels: Sequence[str]):
        labels = tuple(labels)
        self.n = len(labels)
        self._raw = RawMessage(labelled_array(np.zeros(self.n), labels, 0),
                               doubles={"data": ("data", STAMP_PAD + self.n)})
        self._data = self._raw.f["data"]

    def msg(self, values: np.ndarray, stamp_ns: int) -> bytes:
        return bytes(self.write(values, stamp_ns))

    def write(self, values: np.ndarray, stamp_ns: int) -> bytearray:
        d = self._data
        d[0], d[1] = divmod(int(stamp_ns), NS_PER_S)
        d[STAMP_PAD:] = values
        return self._raw.buffer


class RawOdometryBatch:
    """:func:`~msg_bridge.convert.body_odometry` of several bodies as serialised bytes:
    ``w.msgs(x, stamp_ns, P=None)`` gives one message per body, in the order given.

    The bodies' messages live in one buffer, each placed so that its float64 fields fall on one
    8-byte grid; every estimate is then written with a few numpy calls for all the bodies at once
    (positions and velocities from ``x``, the pose and twist covariance blocks of each body's
    states from ``P``, the stamps), not a few per body. Without ``P`` every variance is
    :data:`~msg_bridge.convert.UNESTIMATED_VARIANCE`, as :func:`~msg_bridge.convert.body_odometry`
    writes it.
    """

    def __init__(self, bodies: Sequence[Body], frame_id: str, child_frame_ids: Sequence[str]):
        self.bodies = tuple(bodies)
        n = max((i for b in self.bodies for i in b.indices), default=-1) + 1
        raws = [RawMessage(body_odometry(np.zeros(n), b, 0, frame_id, c), stamp="header.stamp", doubles={
            "pos": ("pose.pose.position.x", 2), "vel": ("twist.twist.linear.x", 2),
            "pc": ("pose.covariance", 36), "tc": ("twist.covariance", 36)})
                for b, c in zip(self.bodies, child_frame_ids)]
        spans, start = [], 0
        for r in raws:                          # each message's doubles on the buffer's 8-byte grid
            start += (-(start + r.offsets["pos"])) % 8
            spans.append((start, start + len(r.buffer)))
            start = spans[-1][1]
        self._buf = bytearray(start + 8)
        for (a, b), r in zip(spans, raws):
            self._buf[a:b] = r.buffer
        self._spans = tuple(spans)
        self._mv = memoryview(self._buf)
        self._f = np.frombuffer(self._buf, dtype="<f8", count=start // 8)
        if any((a + r.offsets["stamp"]) % 4 for (a, _), r in zip(spans, raws)):
            raise ValueError("raw odometry: a stamp is not on the 4-byte grid")
        self._i = np.frombuffer(self._buf, dtype="<i4", count=start // 4)
        x_dst, x_src, p_dst, p_src, cov = [], [], [], [], []
        for (a, _), r, b in zip(spans, raws, self.bodies):
            def at(name, k, a=a, r=r):          # the buffer's float64 index of element k of field name
                return (a + r.offsets[name]) // 8 + k
            for field, cov_field, pairs in (("pos", "pc", b.pose_pairs), ("vel", "tc", b.twist_pairs)):
                for ax, i in pairs:
                    x_dst.append(at(field, ax))
                    x_src.append(i)
                    for ax2, j in pairs:
                        p_dst.append(at(cov_field, 6 * ax + ax2))
                        p_src.append(i * n + j)
                cov += range(at(cov_field, 0), at(cov_field, 36))
        ip = np.intp
        self._x_dst, self._x_src = np.array(x_dst, ip), np.array(x_src, ip)
        self._p_dst, self._p_src, self._cov = np.array(p_dst, ip), np.array(p_src, ip), np.array(cov, ip)
        self._unknown = self._f[self._cov].copy()       # the templates' covariances: P not known
        self._sec = np.array([(a + r.offsets["stamp"]) // 4 for (a, _), r in zip(spans, raws)], ip)
        self.n = n
        self._has_P = False

    def msgs(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None) -> list[bytes]:
        f = self._f
        f[self._x_dst] = x[self._x_src]
        if P is not None:
            f[self._p_dst] = P.reshape(-1)[self._p_src]
            self._has_P = True
        elif self._has_P:                       # back to "not known"
            f[self._cov] = self._unknown
            self._has_P = False
        sec, nsec = divmod(int(stamp_ns), NS_PER_S)
        self._i[self._sec] = sec
        self._i[self._sec + 1] = nsec
        mv = self._mv
        return [bytes(mv[a:b]) for a, b in self._spans]
