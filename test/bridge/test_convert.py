"""msg_bridge: round trips and rejection reasons, messages built in memory (no node)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import Float64MultiArray, UInt8

import msg_bridge as mb
from msg_bridge import Reason

LABELS = tuple(f"{b}.{q}" for b in ("camera", "agent1", "agent2") for q in ("p_x", "p_y", "v_x", "v_y"))


def test_stamp_roundtrip_exact():
    for ns in (1, 999_999_999, 1_000_000_000, 1_795_289_621_926_033_083):
        st = mb.ns_to_stamp(ns)
        assert mb.stamp_to_ns(st) == ns
        assert 0 <= st.nanosec < 1_000_000_000
    with pytest.raises(ValueError, match=">= 0"):
        mb.ns_to_stamp(-1)


def test_pose_roundtrip():
    msg = mb.xy_to_pose((1.25, -3.5), 1_700_000_000_123_456_789, "map")
    assert isinstance(msg, PoseStamped)
    assert msg.header.frame_id == "map"
    assert mb.stamp_to_ns(msg.header.stamp) == 1_700_000_000_123_456_789
    assert msg.pose.orientation.w == 1.0
    np.testing.assert_array_equal(mb.pose_to_xy(msg), [1.25, -3.5])


def test_labelled_array_roundtrip_and_layout():
    x = np.arange(12) * 0.5 - 2.0
    msg = mb.labelled_array(x, LABELS, 1_700_000_000_000_000_001)
    assert isinstance(msg, Float64MultiArray)
    assert msg.layout.data_offset == mb.STAMP_PAD == 2
    assert len(msg.layout.dim) == 1
    dim = msg.layout.dim[0]
    assert (dim.size, dim.stride) == (12, 12)
    assert dim.label.split(",") == list(LABELS)
    arr = mb.unpack_labelled(msg)
    assert arr.stamp_ns == 1_700_000_000_000_000_001
    assert arr.labels == LABELS
    np.testing.assert_array_equal(arr.values, x)
    # a reader that honours data_offset sees exactly the values
    np.testing.assert_array_equal(np.asarray(msg.data)[msg.layout.data_offset:], x)


def test_labelled_array_rejects_mismatch():
    with pytest.raises(ValueError, match="12 values but 3 labels"):
        mb.labelled_array(np.zeros(12), ("a", "b", "c"), 1)
    with pytest.raises(ValueError, match="','"):
        mb.labelled_array([1.0], ("a,b",), 1)
    bad = Float64MultiArray(data=[1.0, 2.0])
    with pytest.raises(ValueError, match="not a labelled switchobs array"):
        mb.unpack_labelled(bad)


def test_envelope_labels():
    assert mb.envelope_labels(2) == ("z_1", "z_2", "paper_bound", "exact_bound")
    assert mb.envelope_labels(3)[:3] == ("z_1", "z_2", "z_3")


def test_bodies_and_odometry():
    bodies = mb.bodies(LABELS)
    assert [b.name for b in bodies] == ["camera", "agent1", "agent2"]
    assert (bodies[1].p_x, bodies[1].p_y, bodies[1].v_x, bodies[1].v_y) == (4, 5, 6, 7)
    x = np.arange(12, dtype=float)
    odoms = mb.state_odometries(x, bodies, 5_000_000_123, "map")
    assert [o.child_frame_id for o in odoms] == ["camera", "agent1", "agent2"]
    o = odoms[2]
    assert o.header.frame_id == "map" and mb.stamp_to_ns(o.header.stamp) == 5_000_000_123
    assert (o.pose.pose.position.x, o.pose.pose.position.y) == (8.0, 9.0)
    assert (o.twist.twist.linear.x, o.twist.twist.linear.y) == (10.0, 11.0)
    assert mb.bodies(("a", "b.v_x", "b.v_y")) == ()   # velocity alone: no body (nothing to place)


def test_every_body_with_a_position_gets_odometry():
    """A landmark (position only), a body on a line (``<body>.p``, ``.v``) and bare ``p<k>``, ``v<k>``
    (config/cart_pair.yaml) are bodies; odometry holds what they have, 0 and a large variance elsewhere;
    the start-up line names the bodies and the states no output shows."""
    labels = ("robot.p_x", "robot.p_y", "robot.v_x", "robot.v_y", "lm1.p_x", "lm1.p_y", "cart.p", "cart.v",
              "p3", "v3", "bias", "w.v_x")
    bodies = mb.bodies(labels)
    assert bodies == (mb.Body("robot", 0, 1, 2, 3), mb.Body("lm1", 4, 5), mb.Body("cart", 6, None, 7),
                      mb.Body("body3", 8, None, 9))
    assert mb.unused_states(labels) == ("bias", "w.v_x")
    assert mb.describe_bodies(labels) == (
        "outputs: 4 bodies with odometry and markers: robot (robot.p_x, robot.p_y, robot.v_x, robot.v_y); "
        "lm1 (lm1.p_x, lm1.p_y); cart (cart.p, cart.v); body3 (p3, v3); states on no odometry or marker "
        "(only ~/state): bias, w.v_x")
    assert [b.name for b in mb.bodies(("p1", "v1", "p2", "v2"))] == ["body1", "body2"]     # cart_pair
    rng = np.random.default_rng(1)
    M = rng.normal(size=(12, 12))
    P = M @ M.T
    x = rng.normal(size=12)
    lm, cart = bodies[1], bodies[2]
    for m in (mb.body_odometry(x, lm, 5, "map", "lm1", P=P), mb.OdometryWriter(lm, "map", "lm1").msg(x, 5, P)):
        assert (m.pose.pose.position.x, m.pose.pose.position.y) == (x[4], x[5])
        assert (m.twist.twist.linear.x, m.twist.twist.linear.y) == (0.0, 0.0)
        pose, twist = np.reshape(m.pose.covariance, (6, 6)), np.reshape(m.twist.covariance, (6, 6))
        np.testing.assert_array_equal(pose[:2, :2], P[4:6, 4:6])
        assert np.all(np.diag(twist) == mb.UNESTIMATED_VARIANCE), "no velocity state: not estimated"
    for m in (mb.body_odometry(x, cart, 5, "map", "cart", P=P), mb.OdometryWriter(cart, "map", "cart").msg(x, 5, P)):
        assert (m.pose.pose.position.x, m.pose.pose.position.y, m.twist.twist.linear.x) == (x[6], 0.0, x[7])
        pose, twist = np.reshape(m.pose.covariance, (6, 6)), np.reshape(m.twist.covariance, (6, 6))
        assert (pose[0, 0], pose[1, 1], twist[0, 0], twist[1, 1]) == (P[6, 6], mb.UNESTIMATED_VARIANCE, P[7, 7],
                                                                      mb.UNESTIMATED_VARIANCE)
        assert pose[0, 1] == 0.0
    w = mb.MarkersWriter(bodies, "map")
    arr = w.msg(x, 7, P, bound=0.5)
    assert len(arr.markers) == 16
    pos = {m.id: m for m in arr.markers if m.ns == "switchobs/position"}
    assert (pos[1].pose.position.x, pos[1].pose.position.y) == (x[4], x[5])
    assert (pos[2].pose.position.x, pos[2].pose.position.y) == (x[6], 0.0)
    ell = {m.id: m for m in arr.markers if m.ns == "switchobs/covariance"}
    assert ell[2].action == ell[2].ADD and ell[2].scale.x == pytest.approx(4.0 * math.sqrt(P[6, 6]), rel=1e-12)
    assert ell[2].scale.y == pytest.approx(0.01) and ell[2].pose.orientation.z == pytest.approx(0.0, abs=1e-15)


def _pose(x=1.0, y=2.0, ns=10_000_000_000, frame="map"):
    return mb.xy_to_pose((x, y), ns, frame)


@pytest.mark.parametrize("field,value,reason", [
    ("x", math.nan, Reason.NON_FINITE), ("y", math.inf, Reason.NON_FINITE), ("z", -math.inf, Reason.NON_FINITE),
    ("x", 1e300, Reason.TOO_LARGE), ("y", -2e6, Reason.TOO_LARGE),
])
def test_check_pose_values(field, value, reason):
    msg = _pose()
    setattr(msg.pose.position, field, value)
    rej = mb.check_pose(msg, frame_id="map", max_abs=1e6)
    assert rej is not None and rej.reason is reason and rej.field == f"pose.position.{field}"


def test_check_pose_orientation_nan():
    msg = _pose()
    msg.pose.orientation.w = math.nan
    assert mb.check_pose(msg).reason is Reason.NON_FINITE


def test_check_pose_frame_and_stamps():
    assert mb.check_pose(_pose(), frame_id="map", last_ns=9_000_000_000, now_ns=10_000_000_000) is None
    assert mb.check_pose(_pose(frame="odom"), frame_id="map").reason is Reason.WRONG_FRAME
    assert mb.check_pose(_pose(frame="odom"), frame_id="") is None        # '' accepts any frame
    assert mb.check_pose(_pose(ns=0)).reason is Reason.ZERO_STAMP
    assert mb.check_pose(_pose(), last_ns=10_000_000_000).reason is Reason.DUPLICATE_STAMP
    assert mb.check_pose(_pose(), last_ns=10_000_000_001).reason is Reason.OLD_STAMP
    rej = mb.check_pose(_pose(ns=11_000_000_000), now_ns=10_000_000_000, future_tolerance_ns=500_000_000)
    assert rej.reason is Reason.FUTURE_STAMP and "1.000000 s ahead" in rej.detail
    assert mb.check_pose(_pose(ns=10_400_000_000), now_ns=10_000_000_000, future_tolerance_ns=500_000_000) is None
    # a sim clock that has not ticked (now = 0) skips the future check
    assert mb.check_pose(_pose(ns=11_000_000_000), now_ns=0) is None


@pytest.mark.parametrize("value,ok", [(0, False), (1, True), (2, True), (3, False), (255, False)])
def test_check_channel(value, ok):
    rej = mb.check_channel(UInt8(data=value), 2)
    assert (rej is None) == ok
    if not ok:
        assert rej.reason is Reason.BAD_CHANNEL and str(value) in rej.detail


def test_bridge_error_carries_rejection():
    rej = mb.check_pose(_pose(ns=0))
    err = mb.BridgeError(rej)
    assert isinstance(err, ValueError) and err.rejection is rej and "zero_stamp" in str(err)


def test_writers_match_the_functions():
    x = np.linspace(-1, 1, 12)
    w = mb.LabelledArrayWriter(LABELS)
    for stamp in (1_000_000_007, 2_500_000_000):
        a = mb.unpack_labelled(w.msg(x * stamp, stamp))
        b = mb.unpack_labelled(mb.labelled_array(x * stamp, LABELS, stamp))
        assert a.stamp_ns == b.stamp_ns == stamp and a.labels == b.labels
        np.testing.assert_array_equal(a.values, b.values)
    body = mb.bodies(LABELS)[1]
    ow = mb.OdometryWriter(body, "map", "a1")
    for stamp in (3_000_000_001, 4_000_000_002):
        o, ref = ow.msg(x * stamp, stamp), mb.body_odometry(x * stamp, body, stamp, "map", "a1")
        assert o == ref


def test_odometry_covariance_from_P_and_large_for_unestimated():
    """Odometry carries the (p_x, p_y) and (v_x, v_y) blocks of P; z, roll, pitch, yaw and their
    rates (and everything, when no P is known) get a large variance, never zero ("certain")."""
    labels = [f"{b}.{q}" for b in ("camera", "agent1") for q in ("p_x", "p_y", "v_x", "v_y")]
    body = mb.bodies(labels)[1]
    rng = np.random.default_rng(0)
    M = rng.normal(size=(8, 8))
    P = M @ M.T
    x = rng.normal(size=8)
    for m in (mb.body_odometry(x, body, 5, "map", "agent1", P=P),
              mb.OdometryWriter(body, "map", "agent1").msg(x, 5, P)):
        pose = np.reshape(m.pose.covariance, (6, 6))
        twist = np.reshape(m.twist.covariance, (6, 6))
        np.testing.assert_array_equal(pose[:2, :2], P[4:6, 4:6])
        np.testing.assert_array_equal(twist[:2, :2], P[6:8, 6:8])
        assert np.all(np.diag(pose)[2:] == mb.UNESTIMATED_VARIANCE)
        assert np.all(np.diag(twist)[2:] == mb.UNESTIMATED_VARIANCE)
    unknown = np.reshape(mb.body_odometry(x, body, 5, "map", "agent1").pose.covariance, (6, 6))
    assert np.all(np.diag(unknown) == mb.UNESTIMATED_VARIANCE)
    assert len(mb.covariance_labels(labels)) == 64 and mb.covariance_labels(labels)[1] == "camera.p_x|camera.p_y"
