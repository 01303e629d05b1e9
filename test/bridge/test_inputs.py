"""msg_bridge.fields and msg_bridge.inputs: one converter per message type and the input
specifications (topic, type, fields -> rows, channel). Messages are built in memory; no node."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import msg_bridge as mb
from msg_bridge import SpecError
from switchobs_core.model.scenarios import load_noise, load_system
from switchobs_core.model.system import LTISystem

ROOT = Path(__file__).resolve().parents[2]
CART = ROOT / "config" / "cart_pair.yaml"
MAX_STAMP_NS = (2**31 - 1) * 1_000_000_000 + 999_999_999   # builtin_interfaces/Time.sec is an int32

#: The paper's interface written as an inputs: section (the brief's example).
PAPER_SECTION = {
    "channel_topic": "camera/active_channel",
    "sources": [
        {"topic": "camera/pose", "type": "geometry_msgs/PoseStamped",
         "fields": ["pose.position.x", "pose.position.y"], "rows": ["camera.p_x", "camera.p_y"]},
        {"topic": "target/pose", "type": "geometry_msgs/PoseStamped",
         "fields": ["pose.position.x", "pose.position.y"], "rows": [2, 3]},
    ],
}


@pytest.fixture(scope="module")
def paper() -> LTISystem:
    return load_system("paper")


@pytest.fixture(scope="module")
def cart() -> LTISystem:
    return load_system(CART)


def _one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert text and "\n" not in text, text
    return text


# ----------------------------------------------------------------------------- converters

@st.composite
def _typed_fields(draw):
    t = draw(st.sampled_from(mb.SUPPORTED_TYPES))
    if t == mb.LABELLED_ARRAY:
        pool = [f"y{k}" for k in range(8)] + ["camera.p_x", "agent 1 [m]", "r"]
        fields = draw(st.lists(st.sampled_from(pool), min_size=1, max_size=6, unique=True))
    else:
        fields = draw(st.lists(st.sampled_from(mb.float64_fields(t)), min_size=1, max_size=5, unique=True))
    return t, fields


@settings(max_examples=300, deadline=None)
@given(tf=_typed_fields(), data=st.data(),
       stamp=st.integers(0, MAX_STAMP_NS),
       frame=st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=12))
def test_every_reader_reads_what_its_writer_wrote(tf, data, stamp, frame):
    t, fields = tf
    values = data.draw(st.lists(st.floats(allow_nan=False, width=64), min_size=len(fields), max_size=len(fields)))
    msg = mb.FieldWriter(t, fields).msg(values, stamp, frame)
    assert isinstance(msg, mb.message_class(t))
    got_stamp, got_frame, y = mb.FieldReader(t, fields).read(msg)
    assert got_stamp == stamp and isinstance(got_stamp, int)
    assert got_frame == ("" if t == mb.LABELLED_ARRAY else frame)
    assert y.dtype == np.float64 and y.shape == (len(fields),)
    np.testing.assert_array_equal(y, values)
    # a reader of the fields in another order gives them in that order
    rev = list(reversed(fields))
    np.testing.assert_array_equal(mb.FieldReader(t, rev).read(msg)[2], list(reversed(values)))


@pytest.mark.parametrize("t", [t for t in mb.SUPPORTED_TYPES if t != mb.LABELLED_ARRAY])
def test_writer_leaves_other_fields_at_zero_with_identity_orientation(t):
    first = mb.float64_fields(t)[0]
    msg = mb.FieldWriter(t, [first]).msg([7.5], 3, "map")
    rest = [f for f in mb.float64_fields(t) if f != first]
    got = dict(zip(rest, mb.FieldReader(t, rest).read(msg)[2]))
    for f, v in got.items():
        assert v == (1.0 if f.endswith("orientation.w") else 0.0), f
    assert mb.FieldReader(t, [first]).read(msg)[2][0] == 7.5


def test_writer_returns_a_new_message_per_call():
    w = mb.FieldWriter("geometry_msgs/PointStamped", ["point.x"])
    a, b = w.msg([1.0], 1, "map"), w.msg([2.0], 2, "map")
    assert a is not b and a.point.x == 1.0 and b.point.x == 2.0


def test_writer_checks_the_number_of_values():
    w = mb.FieldWriter("geometry_msgs/PoseStamped", ["pose.position.x", "pose.position.y"])
    with pytest.raises(mb.BridgeError, match="1 values for 2 fields"):
        w.msg([1.0], 1, "map")


def test_type_names_normalise_and_give_the_rclpy_class():
    from geometry_msgs.msg import PointStamped
    from nav_msgs.msg import Odometry
    assert mb.canonical_type("geometry_msgs/PointStamped") == "geometry_msgs/msg/PointStamped"
    assert mb.canonical_type("nav_msgs/msg/Odometry") == "nav_msgs/msg/Odometry"
    assert mb.message_class("geometry_msgs/PointStamped") is PointStamped
    assert mb.message_class("nav_msgs/msg/Odometry") is Odometry
    assert set(mb.SUPPORTED_TYPES) == {
        "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PointStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry", "std_msgs/msg/Float64MultiArray",
        "geometry_msgs/msg/TwistStamped", "geometry_msgs/msg/AccelStamped"}
    assert mb.float64_fields("geometry_msgs/AccelStamped")[:2] == ("accel.linear.x", "accel.linear.y")
    assert mb.float64_fields("geometry_msgs/PointStamped") == ("point.x", "point.y", "point.z")
    assert "twist.twist.linear.x" in mb.float64_fields("nav_msgs/Odometry")


@pytest.mark.parametrize("t, fields, match", [
    ("geometry_msgs/Pose", ["position.x"], r"message type 'geometry_msgs/Pose' is not supported; supported: "),
    ("sensor_msgs/msg/Imu", ["x"], "is not supported"),
    ("geometry_msgs/PointStamped", ["point.w"],
     r"geometry_msgs/msg/PointStamped has no float64 field 'point.w'; its float64 fields: point.x, point.y, point.z"),
    ("geometry_msgs/PoseStamped", ["header.stamp.sec"], "has no float64 field 'header.stamp.sec'"),
    ("geometry_msgs/PoseStamped", ["pose.position"], "has no float64 field 'pose.position'"),
    ("nav_msgs/Odometry", ["pose.covariance"], "has no float64 field 'pose.covariance'"),
    ("nav_msgs/Odometry", ["twist.linear.x"], "has no float64 field 'twist.linear.x'"),
    ("geometry_msgs/PoseStamped", [], "no fields given"),
    ("geometry_msgs/PoseStamped", "pose.position.x", "fields must be a list"),
    ("geometry_msgs/PoseStamped", ["pose.position.x", "pose.position.x"], "field 'pose.position.x' is given twice"),
    ("geometry_msgs/PoseStamped", [3], "a field must be a non-empty string; got 3"),
    ("std_msgs/Float64MultiArray", ["a,b"], "cannot be an element label"),
    ("std_msgs/Float64MultiArray", [""], "non-empty string"),
])
def test_bad_type_or_field_is_one_line_spec_error(t, fields, match):
    for cls in (mb.FieldReader, mb.FieldWriter):
        with pytest.raises(SpecError, match=match) as err:
            cls(t, fields)
        _one_line(err)


def test_covariance_of_the_types_that_carry_one():
    cov = np.arange(36.0).reshape(6, 6)
    for t in ("geometry_msgs/PoseWithCovarianceStamped", "nav_msgs/Odometry"):
        msg = mb.FieldWriter(t, ["pose.pose.position.x"]).msg([1.0], 5, "map")
        msg.pose.covariance = cov.ravel()
        got = mb.FieldReader(t, ["pose.pose.position.x"]).covariance(msg)
        np.testing.assert_array_equal(got, cov)
    for t, f in (("geometry_msgs/PoseStamped", "pose.position.x"), ("geometry_msgs/PointStamped", "point.x"),
                 ("std_msgs/Float64MultiArray", "a")):
        msg = mb.FieldWriter(t, [f]).msg([1.0], 5, "map")
        assert mb.FieldReader(t, [f]).covariance(msg) is None


def test_reader_is_duck_typed():
    """The bag tools' light CDR views carry the same attribute paths as rclpy messages."""
    ns = SimpleNamespace
    msg = ns(header=ns(stamp=ns(sec=3, nanosec=7), frame_id="map"), point=ns(x=1.5, y=-2.0, z=0.0))
    assert mb.FieldReader("geometry_msgs/PointStamped", ["point.y", "point.x"]).read(msg)[:2] == (3_000_000_007, "map")
    np.testing.assert_array_equal(mb.FieldReader("geometry_msgs/PointStamped", ["point.y", "point.x"]).read(msg)[2],
                                  [-2.0, 1.5])


def test_reader_refuses_a_header_stamp_that_is_no_time():
    r = mb.FieldReader("geometry_msgs/PointStamped", ["point.x"])
    for sec, nsec in ((0, 1_000_000_000), (-1, 0)):
        msg = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nsec), frame_id=""),
                              point=SimpleNamespace(x=1.0))
        with pytest.raises(mb.BridgeError, match=rf"header.stamp: sec {sec}, nanosec {nsec} is not a valid") as err:
            r.read(msg)
        assert err.value.rejection.reason is mb.Reason.BAD_STAMP


def test_check_values_names_the_first_bad_field():
    f = ["point.x", "point.y", "point.z"]
    assert mb.check_values(np.array([1.0, -1e6, 0.0]), f) is None
    rej = mb.check_values(np.array([1.0, np.nan, np.inf]), f)
    assert (rej.reason, rej.field) == (mb.Reason.NON_FINITE, "point.y")
    rej = mb.check_values(np.array([2e6, 0.0, -np.inf]), f, max_abs=1e6)
    assert (rej.reason, rej.field, rej.detail) == (mb.Reason.TOO_LARGE, "point.x", "|2e+06| > 1e+06")


def test_labelled_reader_follows_a_layout_change_and_refuses_other_layouts():
    from std_msgs.msg import Float64MultiArray
    r = mb.FieldReader("std_msgs/Float64MultiArray", ["b", "a"])
    np.testing.assert_array_equal(r.read(mb.labelled_array([1.0, 2.0], ["a", "b"], 9))[2], [2.0, 1.0])
    np.testing.assert_array_equal(r.read(mb.labelled_array([1.0, 2.0, 3.0], ["c", "a", "b"], 9))[2], [3.0, 2.0])
    cases = [
        (Float64MultiArray(data=[1.0, 2.0]), "not a labelled switchobs array"),
        (mb.labelled_array([1.0, 2.0], ["a", "c"], 9), r"labelled array has no element 'b'; its labels: a, c"),
    ]
    short = mb.labelled_array([1.0, 2.0], ["a", "b"], 9)
    short.data = [0.0, 9.0, 1.0]
    cases.append((short, "1 elements after the stamp; its layout says 2"))
    for bad_stamp in ([-1.0, 0.0], [float("nan"), 0.0], [1.0, 1e9], [1.5, 0.0]):
        m = mb.labelled_array([1.0, 2.0], ["a", "b"], 9)
        m.data = bad_stamp + [1.0, 2.0]
        cases.append((m, "is not a valid time"))
    for msg, match in cases:
        with pytest.raises(mb.BridgeError, match=match) as err:
            r.read(msg)
        _one_line(err)


# ----------------------------------------------------------------------------- input specifications

_DROP = object()


def _src(**kw):
    base = {"topic": "left/point", "type": "geometry_msgs/PointStamped", "channel": 1, "fields": ["point.x"],
            "rows": [0]}
    base.update(kw)
    return {k: v for k, v in base.items() if v is not _DROP}


def test_default_inputs_of_paper_and_camera_agents_are_the_paper_interface(paper):
    for system in (paper, load_system("camera_agents")):
        d = mb.default_inputs(system)
        assert d == mb.parse_inputs(PAPER_SECTION, system)
        assert d.channel_topic == "camera/active_channel" and d.uncovered == ()
        cam, tgt = d.sources
        assert (cam.topic, tgt.topic) == ("camera/pose", "target/pose")
        for s in d.sources:
            assert s.type == "geometry_msgs/msg/PoseStamped" and s.channel is None
            assert s.fields == ("pose.position.x", "pose.position.y")
        assert cam.shared and not tgt.shared
        for c in range(1, system.N + 1):
            assert cam.rows_for(c) == (0, 1) and tgt.rows_for(c) == (2, 3)
            assert d.shared_rows(c) == (0, 1)
        assert mb.load_inputs("paper", system) == d
    assert mb.default_inputs(load_system("camera_agents")).sources[1].channel_rows == ((2, 3),) * 2


def test_default_inputs_with_labels_in_another_order(paper):
    """The camera/target interface accepts outputs in any order (rows per channel)."""
    C2 = paper.C[1][[3, 2, 1, 0]]
    labels2 = tuple(reversed(paper.output_labels[1]))
    sys_ = LTISystem(paper.A, None, [paper.C[0], C2], name="swapped", state_labels=paper.state_labels,
                     output_labels=[paper.output_labels[0], labels2])
    d = mb.default_inputs(sys_)
    cam, tgt = d.sources
    assert cam.shared and cam.rows_for(1) == (0, 1) and cam.rows_for(2) == (3, 2)
    assert tgt.rows_for(1) == (2, 3) and tgt.rows_for(2) == (1, 0)
    assert d.shared_rows(2) == (3, 2)
    assert "2: [1, 0]" in d.describe()


def test_default_inputs_refuses_another_system_in_one_line(cart, paper):
    with pytest.raises(SpecError, match=r"system 'cart_pair' has no inputs: section .* channel 1 outputs \['y1\[0\]'\]"
                       r".*add an inputs: section to the system file, e.g. inputs: \{sources: ") as err:
        mb.default_inputs(cart)
    _one_line(err)
    with pytest.raises(SpecError, match="expected cam.p_x, cam.p_y"):
        mb.default_inputs(paper, camera_body="cam")


def test_cart_pair_file_loads_as_a_system_and_as_inputs(cart):
    assert cart.name == "cart_pair" and cart.N == 2
    specs = mb.load_inputs(str(CART), cart)
    assert specs.channel_topic is None and specs.uncovered == ()
    left, right = specs.sources
    assert (left.topic, left.channel, left.rows, left.fields) == ("left/point", 1, (0,), ("point.x",))
    assert (right.topic, right.channel, right.rows) == ("right/point", 2, (0,))
    assert left.type == right.type == "geometry_msgs/msg/PointStamped"
    assert left.rows_for(2) == () and right.rows_for(1) == () and specs.shared_rows(1) == ()
    assert specs.describe().count("\n") == 3
    assert specs.describe().endswith("control ~/control (std_msgs/msg/Float64MultiArray) ['u_1'] -> u[0..0]")
    load_noise(str(CART), cart)                    # the noise reader ignores the inputs: section too


def test_control_topic_of_a_system_with_inputs(cart, paper):
    """cart_pair has B (m = 1): ~/control by default, a labelled array u_1; another stamped type through
    inputs.control; the paper system (m = 0) takes none, and refuses one."""
    assert mb.load_inputs(str(CART), cart).control == mb.ControlSpec("~/control", mb.LABELLED_ARRAY, ("u_1",),
                                                                      None)
    assert mb.default_inputs(paper).control is None
    section = {"sources": [{"topic": "left/point", "type": "geometry_msgs/PointStamped", "channel": 1,
                            "fields": ["point.x"], "rows": [0]}],
               "control": {"topic": "cmd_accel", "type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.x"]}}
    c = mb.parse_inputs(section, cart).control
    assert (c.topic, c.type, c.fields) == ("cmd_accel", "geometry_msgs/msg/AccelStamped", ("accel.linear.x",))
    from geometry_msgs.msg import AccelStamped
    m = AccelStamped()
    m.header.stamp.sec, m.accel.linear.x = 3, 0.25
    stamp, _, u = c.reader.read(m)
    assert stamp == 3_000_000_000 and u.tolist() == [0.25]
    for bad, match in [
        ({"type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.x", "accel.linear.y"]},
         r"inputs.control: 2 field\(s\) for an input of m = 1 entries"),
        ({"type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.w"]}, "has no float64 field"),
        ({"fields": ["accel.linear.x"]}, r"missing key\(s\) \['type'\]"),
        ({"type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.x"], "rate": 5}, r"unknown key\(s\)"),
        ({"topic": "left/point", "type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.x"]},
         "is also an input source's or the channel topic"),
        ({"topic": "~ctl", "type": "geometry_msgs/AccelStamped", "fields": ["accel.linear.x"]},
         "not a valid relative topic name"),
    ]:
        with pytest.raises(SpecError, match=match) as err:
            mb.parse_inputs({**section, "control": bad}, cart)
        _one_line(err)
    with pytest.raises(SpecError, match="the system has no input .B has no columns.") as err:
        mb.parse_inputs({**PAPER_SECTION, "control": section["control"]}, paper)
    _one_line(err)


def test_a_scenario_file_with_inputs_loads(tmp_path):
    import yaml
    f = tmp_path / "three.yaml"
    f.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": 3, "inputs": PAPER_SECTION}))
    sys_ = load_system(f)
    assert sys_.N == 3
    assert mb.load_inputs(str(f), sys_) == mb.default_inputs(sys_)


def test_load_inputs_override_file_and_defaults(tmp_path, cart, paper):
    import yaml
    over = tmp_path / "over.yaml"
    section = {"sources": [_src(topic="a/p"), _src(topic="b/p", channel=2)]}
    over.write_text(yaml.safe_dump({"inputs": section}))
    got = mb.load_inputs(str(CART), cart, override=str(over))
    assert [s.topic for s in got.sources] == ["a/p", "b/p"]
    bare = tmp_path / "bare.yaml"
    bare.write_text(yaml.safe_dump({"estimator": {"ros__parameters": {}}}))
    with pytest.raises(SpecError, match="has no top-level 'inputs:' section") as err:
        mb.load_inputs(str(CART), cart, override=str(bare))
    _one_line(err)
    with pytest.raises(SpecError, match="does not exist"):
        mb.load_inputs(str(CART), cart, override=str(tmp_path / "missing.yaml"))
    # a system file without inputs: gives the default, which only camera/target systems fit
    plain = tmp_path / "plain.yaml"
    plain.write_text(yaml.safe_dump({k: v for k, v in yaml.safe_load(CART.read_text()).items() if k != "inputs"}))
    with pytest.raises(SpecError, match="has no inputs: section"):
        mb.load_inputs(str(plain), load_system(plain))
    # an error in a file names the file
    bad = tmp_path / "bad.yaml"
    bad.write_text(CART.read_text().replace("channel: 2", "channel: 3"))
    with pytest.raises(SpecError, match=rf"^{bad}: inputs.sources\[1\] \(right/point\): channel 3 is not one") as err:
        mb.load_inputs(str(bad), load_system(bad))
    _one_line(err)
    assert mb.parse_inputs(None, paper) == mb.default_inputs(paper)


@pytest.mark.parametrize("section, match", [
    # unknown keys, shapes
    ({"sources": [_src()], "channel": 1},
     r"^inputs: unknown key\(s\) \['channel'\] \(known: channel_topic, sources, control\)"),
    ({"sources": [_src(frame="map")]}, r"^inputs.sources\[0\] \(left/point\): unknown key\(s\) \['frame'\]"),
    ([1], "inputs: must be a mapping"),
    ({"sources": "left/point"}, "'sources' must be a list"),
    ({"sources": []}, "no sources; give at least one"),
    ({"sources": [5]}, r"inputs.sources\[0\]: must be a mapping"),
    ({"sources": [_src(rows=_DROP)]}, r"missing key\(s\) \['rows'\]"),
    # types and fields
    ({"sources": [_src(type="geometry_msgs/Point")]},
     r"^inputs.sources\[0\] \(left/point\): message type 'geometry_msgs/Point' is not supported"),
    ({"sources": [_src(fields=["point.q"])]},
     r"^inputs.sources\[0\] \(left/point\): geometry_msgs/msg/PointStamped has no float64 field 'point.q'"),
    # rows
    ({"sources": [_src(rows=[1])]}, r"row 1 is out of range for channel 1 \(rows 0..0: \['y1\[0\]'\]\)"),
    ({"sources": [_src(rows=[-1])]}, "row -1 is out of range"),
    ({"sources": [_src(rows=["p1"])]}, r"channel 1 has no output 'p1'; its outputs: \['y1\[0\]'\]"),
    ({"sources": [_src(rows=[True])]}, "row True must be a 0-based row index or an output label"),
    ({"sources": [_src(rows=0)]}, "rows must be a list"),
    ({"sources": [_src(fields=["point.x", "point.y"])]}, r"2 field\(s\) but 1 row\(s\); give one row per field"),
    ({"sources": [_src(fields=["point.x", "point.y"], rows=[0, 0])]}, "row 0 of channel 1 is given twice"),
    ({"sources": [_src(), _src(topic="left/other")]},
     r"^inputs.sources\[1\] \(left/other\): row 0 of channel 1 is already fed by sources\[0\] \(left/point\)"),
    # topics
    ({"sources": [_src(), _src(channel=2)]},
     r"^inputs.sources\[1\] \(left/point\): topic already used by sources\[0\]"),
    ({"sources": [_src(topic="/left/point")]}, r"^inputs.sources\[0\].topic: '/left/point' is not a valid relative"),
    ({"sources": [_src(topic="left//point")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic="left point")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic="left/")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic="1left")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic="~/left")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic="")]}, "is not a valid relative topic name"),
    ({"sources": [_src(topic=7)]}, "7 is not a valid relative topic name"),
    ({"sources": [_src()], "channel_topic": "active channel"}, r"^inputs.channel_topic: 'active channel' is not"),
    ({"sources": [_src()], "channel_topic": "left/point"}, "the topic is also the channel_topic"),
    # channels
    ({"sources": [_src(channel=0)]}, r"channel 0 is not one of the system's channels 1..2"),
    ({"sources": [_src(channel=3)]}, r"channel 3 is not one of the system's channels 1..2"),
    ({"sources": [_src(channel=True)]}, "channel True is not one of"),
    ({"sources": [_src(channel="1")]}, "channel '1' is not one of"),
    ({"sources": [_src(channel=None)]},
     r"^inputs.sources\[0\] \(left/point\): its rows differ between channels, so one topic carries several "
     r"channels: give channel_topic"),
])
def test_every_spec_mistake_is_one_line_spec_error(cart, section, match):
    with pytest.raises(SpecError, match=match) as err:
        mb.parse_inputs(section, cart)
    _one_line(err)


def test_label_rows_must_resolve_in_every_channel_served(paper):
    ok = {"channel_topic": "camera/active_channel",
          "sources": [{"topic": "a1/pose", "type": "geometry_msgs/PoseStamped", "channel": 1,
                       "fields": ["pose.position.x"], "rows": ["agent1.p_x"]}]}
    assert mb.parse_inputs(ok, paper).sources[0].rows == (2,)
    bad = {"channel_topic": "camera/active_channel",
           "sources": [dict(ok["sources"][0], channel=None)]}
    with pytest.raises(SpecError, match=r"channel 2 has no output 'agent1.p_x'; its outputs: \['camera.p_x'") as err:
        mb.parse_inputs(bad, paper)
    _one_line(err)


def test_uncovered_channel_is_reported_not_refused(cart):
    specs = mb.parse_inputs({"sources": [_src()]}, cart)
    assert specs.uncovered == (2,)
    assert "no source feeds channel(s) [2]" in specs.describe()


def test_shared_rows_need_no_channel_topic(paper):
    """A channel-independent source (equal C rows in every channel) may go without a channel topic."""
    cam_only = {"sources": [PAPER_SECTION["sources"][0]]}
    specs = mb.parse_inputs(cam_only, paper)
    assert specs.sources[0].shared and specs.channel_topic is None
    assert specs.shared_rows(1) == specs.shared_rows(2) == (0, 1)
    # the same fields written as row indices are shared too (the C rows decide, not the spelling)
    by_index = {"sources": [dict(PAPER_SECTION["sources"][0], rows=[0, 1])]}
    assert mb.parse_inputs(by_index, paper) == specs
    # rows 2, 3 are another agent in each channel: not shared, a channel topic is needed
    with pytest.raises(SpecError, match="its rows differ between channels"):
        mb.parse_inputs({"sources": [PAPER_SECTION["sources"][1]]}, paper)


def test_labelled_array_and_odometry_sources(paper):
    section = {"channel_topic": "sel", "sources": [
        {"topic": "cam/odom", "type": "nav_msgs/Odometry", "fields": ["pose.pose.position.y", "pose.pose.position.x"],
         "rows": ["camera.p_y", "camera.p_x"]},
        {"topic": "agents", "type": "std_msgs/Float64MultiArray", "channel": 1, "fields": ["x1", "y1"],
         "rows": [2, 3]},
        {"topic": "agent2/pose", "type": "geometry_msgs/msg/PoseWithCovarianceStamped", "channel": 2,
         "fields": ["pose.pose.position.x", "pose.pose.position.y"], "rows": ["agent2.p_x", "agent2.p_y"]},
    ]}
    specs = mb.parse_inputs(section, paper)
    assert [s.shared for s in specs.sources] == [True, False, False]
    assert specs.sources[0].rows == (1, 0) and specs.shared_rows(2) == (1, 0)
    arr = specs.sources[1]
    msg = mb.FieldWriter(arr.type, ["y1", "x1"]).msg([4.0, 3.0], 11)
    assert arr.reader.read(msg)[0] == 11
    np.testing.assert_array_equal(arr.reader.read(msg)[2], [3.0, 4.0])


def test_cart_pair_file_is_the_tutorial_system_and_its_inputs():
    import yaml
    blocks = re.findall(r"```yaml\n(.*?)```", (ROOT / "docs" / "tutorials" / "own-system.md").read_text(), re.S)
    system = next(yaml.safe_load(b) for b in blocks if "name: cart_pair" in b)
    inputs = next(yaml.safe_load(b) for b in blocks if b.startswith("inputs:"))
    assert yaml.safe_load(CART.read_text()) == {**system, **inputs}


def _timed_refusal(section, system, match):
    """``parse_inputs(section)`` refused with a one-line :class:`SpecError` matching ``match``; its time (s)."""
    import time
    t0 = time.perf_counter()
    with pytest.raises(SpecError, match=match) as err:
        mb.parse_inputs(section, system)
    took = time.perf_counter() - t0
    _one_line(err)
    return took


@pytest.mark.parametrize("case", ["labels_100k", "copies_40k", "sources_9k_duplicate", "sources_9k"])
def test_huge_specifications_are_refused_in_linear_time(paper, case):
    """Specifications far beyond what a system can use are refused in one line in well under a
    second: 100 000 labels and rows in one labelled array, 40 000 copies of one field, 9 000
    sources (a duplicate topic at sources[1], or all distinct). The checks are linear and the
    counts have explicit limits (msg_bridge.MAX_FIELDS fields per source; at most as many sources
    as the channels have rows, and msg_bridge.MAX_SOURCES)."""
    ct = "camera/active_channel"
    if case == "labels_100k":
        section = {"channel_topic": ct, "sources": [{"topic": "t", "type": "std_msgs/Float64MultiArray",
                                                     "fields": [f"y{k}" for k in range(100_000)],
                                                     "rows": list(range(100_000))}]}
        match = r"^inputs.sources\[0\] \(t\): std_msgs/msg/Float64MultiArray: 100000 fields; at most 4096"
    elif case == "copies_40k":
        section = {"channel_topic": ct, "sources": [{"topic": "t", "type": "geometry_msgs/PoseStamped",
                                                     "fields": ["pose.position.x"] * 40_000, "rows": [0] * 40_000}]}
        match = r"^inputs.sources\[0\] \(t\): geometry_msgs/msg/PoseStamped: 40000 fields; at most 4096"
    else:
        src = PAPER_SECTION["sources"][0]
        sources = [dict(src, topic=f"s{k}") for k in range(9_000)]
        if case == "sources_9k_duplicate":
            sources[1] = dict(src, topic="s0")
        match = r"^inputs: 9000 sources; the system's channels have 8 rows in all, so at most 8 sources"
        section = {"channel_topic": ct, "sources": sources}
    assert _timed_refusal(section, paper, match) < 0.25


def test_a_topic_used_twice_is_found_at_its_second_use(paper):
    """The duplicate at sources[1] is refused before sources[2:] are parsed (they would be refused)."""
    src = PAPER_SECTION["sources"][0]
    section = {"channel_topic": "camera/active_channel", "sources": [src, src, *[{"topic": 5}] * 6]}
    with pytest.raises(SpecError, match=r"^inputs.sources\[1\] \(camera/pose\): topic already used by sources\[0\]"):
        mb.parse_inputs(section, paper)


def test_field_reader_counts_are_linear_and_limited():
    """FieldReader's duplicate check is linear (4 000 copies of a field refused at once) and a
    reader takes at most MAX_FIELDS fields."""
    import time
    t0 = time.perf_counter()
    with pytest.raises(SpecError, match="field 'pose.position.y' is given twice") as err:
        mb.FieldReader("geometry_msgs/PoseStamped", ["pose.position.x", *["pose.position.y"] * 4_000,
                                                     "pose.position.x"])
    assert time.perf_counter() - t0 < 0.25
    _one_line(err)
    with pytest.raises(SpecError, match=rf"{mb.MAX_FIELDS + 1} fields; at most {mb.MAX_FIELDS}") as err:
        mb.FieldReader(mb.LABELLED_ARRAY, [f"y{k}" for k in range(mb.MAX_FIELDS + 1)])
    _one_line(err)
    assert len(mb.FieldReader(mb.LABELLED_ARRAY, [f"y{k}" for k in range(mb.MAX_FIELDS)]).fields) == mb.MAX_FIELDS


@pytest.mark.parametrize("topic, match", [
    ("a" * 5000, r"'aaaa\S*' \(5000 characters\) is not a valid topic name: ROS: topic length should not exceed"),
    ("a/" * 124 + "b", r"'a/a/\S*' \(249 characters\) is not a valid topic name: ROS: topic length should not exceed"),
])
def test_topic_names_are_checked_by_ros_rules_at_parse_time(paper, topic, match):
    """A topic name ROS refuses (create_subscription would raise InvalidTopicNameException) is
    refused when the specification is parsed, in one line, by rclpy's own validation of the
    expanded name."""
    section = {"channel_topic": "camera/active_channel",
               "sources": [dict(PAPER_SECTION["sources"][0], topic=topic)]}
    with pytest.raises(SpecError, match=r"^inputs.sources\[0\].topic: " + match) as err:
        mb.parse_inputs(section, paper)
    assert len(_one_line(err)) < 300
    with pytest.raises(SpecError, match=r"^inputs.channel_topic: " + match):
        mb.parse_inputs(dict(PAPER_SECTION, channel_topic=topic), paper)
    # the longest relative name ROS takes under the root namespace is accepted (247 characters expanded)
    ok = "a/" * 122 + "bc"
    assert len("/" + ok) == 247
    assert mb.parse_inputs(dict(PAPER_SECTION, channel_topic=ok), paper).channel_topic == ok
