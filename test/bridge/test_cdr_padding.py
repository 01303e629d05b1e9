"""msg_bridge.cdr_padding and the raw writers' bytes: with the CDR alignment padding zeroed, a message's
bytes are rosbags' ``serialize_cdr`` of it byte for byte (rosbags writes zeros there; rclpy leaves heap
bytes), whatever memory held before: serialised messages are reproducible byte for byte."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Empty, Float64MultiArray, String
from switchobs_msgs.msg import StateEstimate
from visualization_msgs.msg import MarkerArray

import msg_bridge as mb
from msg_bridge.cdr_padding import zero_padding
from msg_bridge.markers import RawMarkersWriter
from msg_bridge.raw import RawLabelledArrayWriter, RawOdometryBatch
from msg_bridge.typed import ErrorBoundsWriter, RawStateEstimateWriter, register_rosbags_types


@pytest.fixture(scope="module")
def store():
    from rosbags.typesys import Stores, get_typestore

    s = get_typestore(Stores.ROS2_JAZZY)
    register_rosbags_types(s)
    return s


def _dirty() -> None:
    """Memory freed full of non-zero bytes, for rclpy's padding to take up (as a process's heap does)."""
    junk = [bytes([0xAB]) * 4096 for _ in range(200)]
    del junk


_DTYPES = {"boolean": np.bool_, "octet": np.uint8, "uint8": np.uint8, "char": np.uint8, "int8": np.int8,
           "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "float": np.float32,
           "int64": np.int64, "uint64": np.uint64, "double": np.float64}


def _converted(store, msg):
    """``msg`` (an rclpy message) as rosbags' message of its type."""
    from rosidl_parser.definition import AbstractNestedType, BasicType, NamespacedType

    def value(v, t):
        if isinstance(t, NamespacedType):
            return _converted(store, v)
        if isinstance(t, AbstractNestedType):
            et = t.value_type
            return np.asarray(v, dtype=_DTYPES[et.typename]) if isinstance(et, BasicType) else [value(i, et) for i in v]
        return v
    names = type(msg).__module__.split(".")
    cls = store.types[f"{names[0]}/{names[1]}/{type(msg).__name__}"]
    return cls(**{f: value(getattr(msg, f), t) for f, t in zip(msg.get_fields_and_field_types(), type(msg).SLOT_TYPES)})


def _assert_rosbags_bytes(store, data, msg, type_name: str) -> None:
    """``data`` is rosbags' serialisation of ``msg`` (zeros in its padding), then zeros only (the length
    rmw_fastrtps gives a message with an empty sequence of primitives)."""
    want = bytes(store.serialize_cdr(_converted(store, msg), type_name))
    assert bytes(data[:len(want)]) == want, type_name
    assert not any(data[len(want):]) and len(data) - len(want) < 8, type_name

LABELS = ("b0.p_x", "b0.p_y", "b0.v_x", "b0.v_y", "b1.p", "b1.v", "p2", "v2")


@settings(max_examples=30, deadline=None)
@given(frame=st.text(max_size=9), why=st.text(max_size=9), note=st.text(max_size=9), n=st.integers(0, 5),
       valid=st.booleans(), stamp=st.integers(0, 2**31 * 10**9 - 1))
def test_zeroed_bytes_are_rosbags_bytes(store, frame, why, note, n, valid, stamp):
    """Strings of every length modulo 8 (unaligned doubles, lengths and booleans after them) and sequences
    of every length, empty ones included."""
    w = ErrorBoundsWriter(n, frame.replace("\0", ""), True)
    msg = w.msg(list(np.linspace(1.0, 2.0, n + 3)), stamp, valid, why.replace("\0", ""), note.replace("\0", ""))
    _dirty()
    _assert_rosbags_bytes(store, zero_padding(msg, serialize_message(msg)), msg, "switchobs_msgs/msg/ErrorBounds")


def test_every_raw_writers_bytes_are_rosbags_bytes(store):
    """The templates the node publishes from: labelled arrays, odometries (frame ids of every length
    modulo 4), the typed state estimate with and without P, the markers."""
    _dirty()
    bodies = mb.bodies(LABELS)
    n = len(LABELS)
    x, P = np.linspace(-1.0, 1.0, n), np.eye(n)
    got = [(RawLabelledArrayWriter(LABELS).msg(x, 7), Float64MultiArray, "std_msgs/msg/Float64MultiArray")]
    batch = RawOdometryBatch(bodies, "map", [f"r/{b.name}" + "x" * k for k, b in enumerate(bodies)])
    got += [(m, Odometry, "nav_msgs/msg/Odometry") for m in batch.msgs(x, 7, P)]
    se = RawStateEstimateWriter(LABELS, "map")
    got += [(se.msg(x, 7, P), StateEstimate, "switchobs_msgs/msg/StateEstimate"),
            (se.msg(x, 7), StateEstimate, "switchobs_msgs/msg/StateEstimate")]
    got.append((RawMarkersWriter(bodies, "map").msg(x, 7, P, 1.0, bodies[0].name), MarkerArray,
                "visualization_msgs/msg/MarkerArray"))
    for data, cls, type_name in got:
        _assert_rosbags_bytes(store, data, deserialize_message(data, cls), type_name)

def test_bytes_that_are_not_the_message_are_refused():
    data = serialize_message(String(data="abcdef"))
    with pytest.raises(ValueError, match="not little-endian"):
        zero_padding(String(data="abcdef"), b"\x00\x00" + data[2:])
    with pytest.raises(ValueError, match="CDR padding"):      # another type's bytes
        zero_padding(Odometry(), data)
    with pytest.raises(ValueError, match="fields end"):
        zero_padding(String(data="abcdef"), data + bytes(4))


def test_a_message_without_fields_is_walked_as_its_hidden_byte():
    """std_msgs/Empty: rosidl gives it one hidden uint8 that its field list does not name; the walk takes it
    (a field after a nested empty message stays where it is) and zeroes what follows."""
    data = serialize_message(Empty())
    assert bytes(zero_padding(Empty(), data)) == bytes(data[:5]) + bytes(len(data) - 5)


@pytest.mark.parametrize("frame", ["", "m", "map", "odom7"])
@pytest.mark.parametrize("n", [0, 1, 2, 5])
def test_sequences_of_fixed_size_messages_are_rosbags_bytes(store, frame, n):
    """Sequences of messages of one size (a line strip's points: 24 bytes each, walked item by item
    until one ends on the 8-byte phase it began on with no padding, the rest taken at once; colours
    of 16 bytes; 12-byte Point32s, never taken at once) after frame ids of every length modulo 8:
    rosbags' bytes."""
    from geometry_msgs.msg import Point, Point32, PolygonStamped
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker

    _dirty()
    m = Marker()
    m.header.frame_id = frame
    m.text = frame * 3
    m.points = [Point(x=0.5 * k, y=-1.0 * k, z=float(k)) for k in range(n)]
    m.colors = [ColorRGBA(r=0.25 * k, a=1.0) for k in range(n)]
    poly = PolygonStamped()
    poly.header.frame_id = frame
    poly.polygon.points = [Point32(x=0.5 * k, y=1.5, z=-2.0) for k in range(n)]
    for msg, type_name in ((m, "visualization_msgs/msg/Marker"), (poly, "geometry_msgs/msg/PolygonStamped")):
        _assert_rosbags_bytes(store, zero_padding(msg, serialize_message(msg)), msg, type_name)
