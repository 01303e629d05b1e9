"""msg_bridge.markers: the content of ~/markers (positions, 2-sigma ellipses, the bound's circle,
the highlight), stable namespaces and ids, and nothing drawn for a withdrawn bound."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import Marker, MarkerArray

import msg_bridge as mb
from msg_bridge.markers import (
    BODY,
    BOUND,
    CIRCLE_POINTS,
    HIGHLIGHT,
    NAMESPACES,
    MarkersWriter,
    ellipse_disc,
    ellipse_discs,
)

LABELS = tuple(f"{b}.{q}" for b in ("camera", "agent1", "agent2") for q in ("p_x", "p_y", "v_x", "v_y"))
NAMES = ("camera", "agent1", "agent2")
S = 1_700_000_000_000_000_007


def _rot(theta: float) -> np.ndarray:
    return np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])


def _state() -> np.ndarray:
    return np.array([1.0, 2.0, 0.1, 0.2, -3.0, 4.5, 0.0, 0.0, 7.25, -1.5, 1.0, 1.0])


def _P(theta: float = math.radians(30.0), l1: float = 4.0, l2: float = 1.0) -> np.ndarray:
    """A 12x12 covariance whose agent1 (p_x, p_y) block is R(theta) diag(l1, l2) R(theta)'."""
    P = np.eye(12) * 0.09
    R = _rot(theta)
    P[4:6, 4:6] = R @ np.diag([l1, l2]) @ R.T
    P[4:6, 0:2] = P[0:2, 4:6] = 0.01      # cross terms do not enter a body's ellipse
    return P


def _by(arr: MarkerArray, ns: str) -> dict[int, Marker]:
    return {m.id: m for m in arr.markers if m.ns == ns}


def _rgba(c) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)


@pytest.fixture
def writer() -> MarkersWriter:
    return MarkersWriter(mb.bodies(LABELS), "map")


def test_positions_labels_frame_and_stamp(writer):
    x = _state()
    arr = writer.msg(x, S)
    assert len(arr.markers) == 4 * len(NAMES)
    pos, lab = _by(arr, "switchobs/position"), _by(arr, "switchobs/label")
    for k, name in enumerate(NAMES):
        assert pos[k].type == Marker.SPHERE and pos[k].action == Marker.ADD
        assert (pos[k].pose.position.x, pos[k].pose.position.y, pos[k].pose.position.z) == (x[4 * k], x[4 * k + 1], 0)
        assert lab[k].type == Marker.TEXT_VIEW_FACING and lab[k].text == name
        assert (lab[k].pose.position.x, lab[k].pose.position.y) == (x[4 * k], x[4 * k + 1])
        assert lab[k].pose.position.z > 0, "the name floats above the sphere"
    for m in arr.markers:
        assert m.header.frame_id == "map" and mb.stamp_to_ns(m.header.stamp) == S
        assert (m.lifetime.sec, m.lifetime.nanosec) == (0, 0)
    # it goes through rclpy's serialisation (colours become float32 on the wire)
    back = deserialize_message(serialize_message(arr), MarkerArray)
    assert [(m.ns, m.id, m.type, m.action, m.pose, m.text) for m in back.markers] \
        == [(m.ns, m.id, m.type, m.action, m.pose, m.text) for m in arr.markers]


def test_covariance_ellipse_axes_are_two_sigma_and_rotated(writer):
    theta, l1, l2 = math.radians(30.0), 4.0, 1.0
    P = _P(theta, l1, l2)
    cov = _by(writer.msg(_state(), S, P), "switchobs/covariance")
    e = cov[1]                                                      # agent1
    assert e.type == Marker.CYLINDER and e.action == Marker.ADD
    # semi-axes 2 sqrt(l): the cylinder's scales are the full axes (diameters)
    assert e.scale.x / 2 == pytest.approx(2 * math.sqrt(l1), rel=1e-12)
    assert e.scale.y / 2 == pytest.approx(2 * math.sqrt(l2), rel=1e-12)
    assert 0 < e.scale.z < 0.05, "a flat disc"
    assert (e.pose.position.x, e.pose.position.y) == (-3.0, 4.5)
    q = e.pose.orientation
    assert (q.x, q.y) == (0.0, 0.0) and q.z ** 2 + q.w ** 2 == pytest.approx(1.0)
    yaw = 2 * math.atan2(q.z, q.w)
    # the major axis is along theta (an axis: modulo pi), and an eigenvector of the block
    assert math.remainder(yaw - theta, math.pi) == pytest.approx(0.0, abs=1e-12)
    v = np.array([math.cos(yaw), math.sin(yaw)])
    np.testing.assert_allclose(P[4:6, 4:6] @ v, l1 * v, atol=1e-12)
    # the other bodies: isotropic 0.09 -> a circle of radius 2 * 0.3
    for k in (0, 2):
        assert cov[k].scale.x == pytest.approx(1.2) and cov[k].scale.y == pytest.approx(1.2)


def test_covariance_ellipse_of_a_rotated_block_beyond_90_degrees(writer):
    theta = math.radians(125.0)
    P = _P(theta, 9.0, 0.25)
    e = _by(writer.msg(_state(), S, P), "switchobs/covariance")[1]
    assert (e.scale.x, e.scale.y) == (pytest.approx(12.0), pytest.approx(2.0))
    yaw = 2 * math.atan2(e.pose.orientation.z, e.pose.orientation.w)
    assert math.remainder(yaw - theta, math.pi) == pytest.approx(0.0, abs=1e-12)


def test_bound_circle_radius_and_closure(writer):
    x, bound = _state(), 0.75
    bnd = _by(writer.msg(x, S, bound=bound), "switchobs/bound")
    assert sorted(bnd) == [0, 1, 2]
    for k, m in bnd.items():
        assert m.type == Marker.LINE_STRIP and m.action == Marker.ADD
        assert _rgba(m.color) == BOUND
        pts = np.array([(p.x, p.y) for p in m.points])
        assert len(pts) == CIRCLE_POINTS
        np.testing.assert_allclose(np.hypot(pts[:, 0] - x[4 * k], pts[:, 1] - x[4 * k + 1]), bound, rtol=1e-12)
        np.testing.assert_allclose(pts[0], pts[-1], atol=1e-12)     # closed
        # it goes round: the points span every direction
        ang = np.sort(np.arctan2(pts[:-1, 1] - x[4 * k + 1], pts[:-1, 0] - x[4 * k]))
        assert np.diff(ang).max() < 2 * math.pi / (CIRCLE_POINTS - 1) + 1e-9


@pytest.mark.parametrize("bound", [None, -1.0, float("nan"), float("inf")])
def test_nothing_drawn_for_a_withdrawn_bound_or_no_covariance(writer, bound):
    x = _state()
    first = writer.msg(x, S, _P(), bound=0.5)
    assert all(m.action == Marker.ADD for m in first.markers)
    arr = writer.msg(x, S + 1, None, bound=bound)
    for ns in ("switchobs/bound", "switchobs/covariance"):
        ms = _by(arr, ns)
        assert len(ms) == 3 and all(m.action == Marker.DELETE for m in ms.values()), \
            f"{ns}: RViz removes what it drew before"
    assert not [m for m in arr.markers if m.ns == "switchobs/bound" and m.action == Marker.ADD]
    assert all(m.action == Marker.ADD for m in _by(arr, "switchobs/position").values())


def test_highlight_of_the_body_in_view(writer):
    x = _state()
    pos = _by(writer.msg(x, S, active_body="agent2"), "switchobs/position")
    assert [_rgba(pos[k].color) for k in range(3)] == [BODY, BODY, HIGHLIGHT]
    pos = _by(writer.msg(x, S, active_body="agent1"), "switchobs/position")
    assert [_rgba(pos[k].color) for k in range(3)] == [BODY, HIGHLIGHT, BODY]
    pos = _by(writer.msg(x, S), "switchobs/position")
    assert all(_rgba(m.color) == BODY for m in pos.values())
    assert HIGHLIGHT != BODY
    with pytest.raises(mb.BridgeError, match="active body 'agent3' is not one of camera, agent1, agent2"):
        writer.msg(x, S, active_body="agent3")


def test_ids_and_namespaces_stable_across_calls(writer):
    x = _state()
    keys = [[(m.ns, m.id) for m in writer.msg(x + i, S + i, _P() if i % 2 else None,
                                             bound=0.3 if i % 3 else None,
                                             active_body=NAMES[i % 3]).markers] for i in range(6)]
    assert all(k == keys[0] for k in keys)
    assert keys[0] == [(ns, k) for k in range(3) for ns in NAMESPACES]
    assert len(set(keys[0])) == len(keys[0]), "each (namespace, id) once"
    # another writer for the same bodies uses the same keys (a restarted node replaces the markers)
    assert [(m.ns, m.id) for m in MarkersWriter(mb.bodies(LABELS), "map").msg(x, S).markers] == keys[0]


@settings(max_examples=40, deadline=None)
@given(kinds=st.lists(st.sampled_from([("p_x", "p_y", "v_x", "v_y"), ("p_x", "p_y"), ("p", "v")]), min_size=1,
                      max_size=8),
       seed=st.integers(0, 2**32 - 1), bad=st.lists(st.sampled_from([math.nan, math.inf, -math.inf]), max_size=3),
       rank=st.sampled_from(["full", "one", "zero"]), scale=st.floats(1e-12, 1e12))
def test_batched_ellipses_are_each_bodys_ellipse(kinds, seed, bad, rank, scale):
    """``ellipse_discs`` (one eigen-decomposition call for all bodies, the raw writer's) gives each
    body exactly what ``ellipse_disc`` gives it alone: planar bodies, bodies on a line, blocks of
    rank 2, 1 or 0, non-finite entries (no ellipse for that body only)."""
    labels = tuple(f"b{k}.{q}" for k, qs in enumerate(kinds) for q in qs)
    bodies = mb.bodies(labels)
    n = len(labels)
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n if rank == "full" else 1 if rank == "one" else 0))
    P = scale * (A @ A.T) if A.size else np.zeros((n, n))
    for v in bad:
        i, j = rng.integers(0, n, 2)
        P[i, j] = v
    got = ellipse_discs(P, bodies)
    assert got == [ellipse_disc(P, b) for b in bodies]
    assert ellipse_discs(None, bodies) == [None] * len(bodies)
