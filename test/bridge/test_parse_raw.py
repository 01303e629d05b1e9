"""msg_bridge.parse: the raw reader gives, from a serialised message, exactly the fields
rclpy's deserialiser gives; bytes that are not such a message are rejected, never raised; the
parsed form and the message are checked by the same code with the same result."""

from __future__ import annotations

import math
import struct
from operator import attrgetter

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from msg_bridge.parse import RAW_TYPES, Parser, RawReader

_doubles = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True, width=64)
_frames = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=40)
_SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _message(type_name: str, sec: int, nsec: int, frame: str, values: list[float]):
    msg = mb.message_class(type_name)()
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
    msg.header.frame_id = frame
    for f, v in zip(mb.float64_fields(type_name), values):
        obj, _, leaf = f.rpartition(".")
        setattr(attrgetter(obj)(msg), leaf, v)
    return msg


def _bits(values) -> list[bytes]:
    return [struct.pack("<d", v) for v in values]


@st.composite
def _messages(draw):
    type_name = draw(st.sampled_from(RAW_TYPES))
    k = len(mb.float64_fields(type_name))
    values = draw(st.lists(_doubles, min_size=k, max_size=k))
    sec = draw(st.integers(-2**31, 2**31 - 1))
    nsec = draw(st.integers(0, 2**32 - 1))
    return type_name, _message(type_name, sec, nsec, draw(_frames), values)


@_SETTINGS
@given(_messages())
def test_raw_reader_gives_the_fields_rclpy_deserialises(case):
    type_name, msg = case
    data = serialize_message(msg)
    got = RawReader(type_name).parse(data)
    back = deserialize_message(data, mb.message_class(type_name))
    assert isinstance(got, tuple), got
    sec, nsec, frame, values = got
    assert (sec, nsec, frame) == (back.header.stamp.sec, back.header.stamp.nanosec, back.header.frame_id)
    want = Parser(type_name, mb.float64_fields(type_name)).parse(back)[3]
    assert len(values) == len(mb.float64_fields(type_name))
    assert _bits(values) == _bits(want)           # bit for bit: nan payloads, -0.0, subnormals
    if type_name == "geometry_msgs/msg/PoseWithCovarianceStamped":       # the fixed array after the fields
        assert np.array_equal(np.frombuffer(data, "<f8", 36, len(data) - 288), back.pose.covariance, equal_nan=True)


@_SETTINGS
@given(_messages(), st.data())
def test_truncated_or_corrupted_bytes_are_rejected_not_raised(case, data):
    type_name, msg = case
    good = serialize_message(msg)
    reader = RawReader(type_name)
    cut = data.draw(st.integers(0, len(good) - 1))
    rej = reader.parse(good[:cut])
    assert isinstance(rej, Rejection) and rej.reason is Reason.BAD_LAYOUT
    assert isinstance(reader.parse(good + b"\x00" * data.draw(st.integers(1, 9))), Rejection)
    # any bytes flipped anywhere: a parse or a rejection, never an exception
    bad = bytearray(good)
    for _ in range(data.draw(st.integers(1, 4))):
        bad[data.draw(st.integers(0, len(bad) - 1))] ^= data.draw(st.integers(1, 255))
    got = reader.parse(bytes(bad))
    assert isinstance(got, (tuple, Rejection))
    if isinstance(got, tuple):      # what the raw reader reads, rclpy reads the same
        back = deserialize_message(bytes(bad), type(msg))
        assert got[:3] == (back.header.stamp.sec, back.header.stamp.nanosec, back.header.frame_id)
        assert _bits(got[3]) == _bits(attrgetter(*mb.float64_fields(type_name))(back))
    # the parser: a parse or a rejection for any of these bytes, never an exception
    for b in (good[:cut], bytes(bad)):
        assert isinstance(Parser(type_name, mb.float64_fields(type_name)[:1]).parse(b), (tuple, Rejection))


def test_malformed_frames_and_encodings_are_bad_layout():
    msg = mb.xy_to_pose((1.0, 2.0), 5_000_000_007, "map")
    data = bytearray(serialize_message(msg))
    reader = RawReader("geometry_msgs/PoseStamped")
    assert reader.parse(bytes(data))[:3] == (5, 7, "map")
    big = bytes(b"\x00\x00" + data[2:])                        # CDR_BE label on little-endian content
    utf = bytes(data[:16] + b"\xff" + data[17:])               # "\xffap": not UTF-8
    nul = bytes(data[:16] + b"\x00" + data[17:])               # a NUL inside the frame
    unterminated = bytes(data[:19] + b"p" + data[20:])         # the terminator overwritten
    long = bytes(data[:12] + struct.pack("<I", 2**32 - 1) + data[16:])
    empty_len = bytes(data[:12] + struct.pack("<I", 0) + data[16:])
    for bad in (big, utf, nul, memoryview(nul), unterminated, long, empty_len, b"", b"\x00\x01"):
        rej = reader.parse(bad)
        assert isinstance(rej, Rejection) and rej.reason is Reason.BAD_LAYOUT, bad


@pytest.mark.parametrize("frame", ["", "map", "ma", "odom_1234", "wörld/frame"])
def test_every_frame_length_and_padding(frame):
    """Each frame length mod 8 (the doubles' padding) read as rclpy reads it."""
    for type_name in RAW_TYPES:
        k = len(mb.float64_fields(type_name))
        msg = _message(type_name, 3, 999_999_999, frame, [math.ldexp(1.0 + j, -1070) for j in range(k)])
        want = Parser(type_name, mb.float64_fields(type_name)).parse(msg)
        assert RawReader(type_name).parse(serialize_message(msg)) == want


@_SETTINGS
@given(st.lists(_doubles, min_size=7, max_size=7), st.integers(-3, 3), st.integers(0, 2**32 - 1),
       st.sampled_from(["map", "odom", ""]), st.one_of(st.none(), st.integers(0, 2 * 10**9)))
def test_check_pose_same_answer_from_bytes_and_message(values, sec, nsec, frame, last_ns):
    """The node's raw input and a Python message are checked by the same code, with the same result."""
    msg = _message("geometry_msgs/PoseStamped", sec, nsec, frame, values)
    kw = dict(frame_id="map", max_abs=1e6, last_ns=last_ns, now_ns=2 * 10**9, future_tolerance_ns=10**8)
    parsed = RawReader("geometry_msgs/PoseStamped").parse(serialize_message(msg))
    assert mb.check_pose(parsed, **kw) == mb.check_pose(msg, **kw)


def test_parser_takes_bytes_messages_and_parsed_forms():
    p = Parser("geometry_msgs/PointStamped", ("point.y",))
    msg = _message("geometry_msgs/PointStamped", 1, 2, "map", [0.5, -1.5, 2.5])
    parsed = p.parse(serialize_message(msg))
    assert parsed == p.parse(msg) == (1, 2, "map", (0.5, -1.5, 2.5))
    assert p.parse(parsed) is parsed
    assert np.array_equal(p.values(parsed[3]), [-1.5])
    odom = Parser("nav_msgs/Odometry", ("twist.twist.linear.x",))
    assert odom.raw is None and odom.parse(b"\x00\x01\x00\x00").reason is Reason.BAD_LAYOUT
    with pytest.raises(ValueError):
        Parser(mb.LABELLED_ARRAY, ("a",))


def _first_bad_value(v, max_abs):
    """check_pose's value rule, field by field: the first non-finite value, or position above max_abs."""
    for k, x in enumerate(v):
        if not math.isfinite(x):
            return Reason.NON_FINITE, k
        if k < 3 and abs(x) > max_abs:
            return Reason.TOO_LARGE, k
    return None


@_SETTINGS
@given(st.lists(st.one_of(_doubles, st.sampled_from([1e308, -1e308, 1e6, 1.0000001e6, math.inf, math.nan])),
                min_size=7, max_size=7),
       st.sampled_from([1e6, 1e300, math.inf, 0.0]))
def test_check_pose_names_the_first_bad_field(values, max_abs):
    rej = mb.check_pose((1, 0, "map", tuple(values)), max_abs=max_abs)
    want = _first_bad_value(values, max_abs)
    if want is None:
        assert rej is None
    else:
        assert (rej.reason, rej.field) == (want[0], mb.float64_fields("geometry_msgs/PoseStamped")[want[1]])


@pytest.mark.parametrize("max_abs", [1e6, math.inf])
@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_check_pose_non_finite_at_each_field_whatever_max_abs(max_abs, bad):
    for k, field in enumerate(mb.float64_fields("geometry_msgs/PoseStamped")):
        v = [1.0, -2.0, 3.0, 0.0, 0.0, 0.0, 1.0]
        v[k] = bad
        rej = mb.check_pose((1, 0, "map", tuple(v)), max_abs=max_abs)
        assert (rej.reason, rej.field) == (Reason.NON_FINITE, field)
    huge = (1e308, 1e308, 1e308, 1e308, 1e308, 1e308, 1e308)       # finite, the sum overflows
    assert mb.check_pose((1, 0, "map", huge), max_abs=math.inf) is None


def _big_endian(sec: int, nsec: int, frame: str, values: list[float]) -> bytes:
    """A PoseStamped in big-endian CDR (encapsulation 0x0000), as a big-endian writer serialises it."""
    name = frame.encode() + b"\x00"
    body = struct.pack(">iII", sec, nsec, len(name)) + name
    body += b"\x00" * (-len(body) % 8) + struct.pack(">7d", *values)
    return b"\x00\x00\x00\x00" + body


@_SETTINGS
@given(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1), _frames, st.lists(_doubles, min_size=7, max_size=7))
def test_parser_reads_big_endian_bytes_as_rclpy_does(sec, nsec, frame, values):
    """Bytes of a big-endian writer are not lost: the raw reader refuses them, the parser hands
    them to rclpy's deserialiser and gives the form of the little-endian bytes of the same message."""
    data = _big_endian(sec, nsec, frame, values)
    assert isinstance(RawReader("geometry_msgs/PoseStamped").parse(data), Rejection)
    got = Parser("geometry_msgs/PoseStamped", ("pose.position.x",)).parse(data)
    want = RawReader("geometry_msgs/PoseStamped").parse(
        serialize_message(_message("geometry_msgs/msg/PoseStamped", sec, nsec, frame, values)))
    assert got[:3] == want[:3] and _bits(got[3]) == _bits(want[3])


def test_parser_rejects_bytes_rclpy_cannot_read_either():
    data = _big_endian(5, 7, "map", [1.0] * 7)
    for bad in (data[:20], b"\x00\x00\x00\x00", b"\x00\x00"):
        rej = Parser("geometry_msgs/PoseStamped", ("pose.position.x",)).parse(bad)
        assert isinstance(rej, Rejection) and rej.reason is Reason.BAD_LAYOUT, bad


def test_parser_reads_the_bytes_the_raw_reader_refuses_as_rclpy_does():
    """One rule for bytes, live and in a bag: what rclpy reads is a message (a frame id that is not
    UTF-8 or holds a NUL, trailing bytes), read into the form of that message; what it cannot read is
    ``bad_layout``; check_pose answers a rejection for such bytes, never raises."""
    data = serialize_message(mb.xy_to_pose((1.0, 2.0), 5_000_000_007, "map"))
    parser = Parser("geometry_msgs/PoseStamped", ("pose.position.x", "pose.position.y"))
    cases = [data[:16] + b"\xff" + data[17:], data[:16] + b"\x00" + data[17:], data + b"\x00" * 8,
             data[:-5], data[:12] + struct.pack("<I", 2**31) + data[16:]]
    read = 0
    for bad in cases:
        assert isinstance(RawReader("geometry_msgs/PoseStamped").parse(bad), Rejection)
        try:
            back = deserialize_message(bad, mb.message_class("geometry_msgs/PoseStamped"))
        except Exception:
            back = None
        got = parser.parse(bad)
        if back is None:
            assert isinstance(got, Rejection) and got.reason is Reason.BAD_LAYOUT
            assert isinstance(mb.check_pose(bad), Rejection)
        else:
            read += 1
            assert got == parser.parse(back)
    assert read >= 2 and read < len(cases)      # both outcomes exercised
