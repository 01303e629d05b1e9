"""The estimator's typed outputs over DDS, beside the labelled arrays: ~/state_estimate
(switchobs_msgs/StateEstimate), ~/error_bounds (ErrorBounds) and ~/markers (MarkerArray for
RViz) carry the same numbers as ~/state and ~/envelope, for the same stamps; the markers put
each body at its estimated position, draw the guaranteed bound, and highlight the body in view.
The markers' publisher appears right after the first estimate (switchobs_ros.late_markers)."""

from __future__ import annotations

import numpy as np
from ros_harness import EstimatorIO, spin_until, start_feed
from switchobs_msgs.msg import ErrorBounds, StateEstimate
from visualization_msgs.msg import Marker, MarkerArray

import msg_bridge as mb
from msg_bridge.typed import read_error_bounds, read_state_estimate
from switchobs_ros import qos
from tools.launch import NodeProcess, ros_args


def test_typed_outputs_and_markers_match_the_labelled_arrays(ros_node, paper_tables, tmp_path):
    proc = NodeProcess("estimator", ros_args(params={"gain_table": paper_tables["periodic"], "e0": 5.0,
                                                     "output.markers_every": 5}), log=tmp_path / "node.log")
    got = {"se": [], "eb": [], "mk": []}
    subs = [ros_node.create_subscription(StateEstimate, "/estimator/state_estimate", got["se"].append, qos.TRUTH),
            ros_node.create_subscription(ErrorBounds, "/estimator/error_bounds", got["eb"].append, qos.TRUTH),
            ros_node.create_subscription(MarkerArray, "/estimator/markers", got["mk"].append, qos.TRUTH)]
    try:
        io = EstimatorIO(ros_node)
        assert io.wait_matched()
        assert spin_until(ros_node, lambda: all(ros_node.count_publishers(s.topic_name) for s in subs[:2]), 20.0)
        assert ros_node.count_publishers("/estimator/markers") == 0     # ~/markers: after the first estimate
        stamps = start_feed(io, 2, 21)
        for k, s in enumerate(stamps):
            io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), s, "map"))
            io.pub_target.publish(mb.xy_to_pose((-2.0, 2.0), s, "map"))
            spin_until(ros_node, lambda: False, 0.01)
            if k == 0:      # the markers of estimates 5, 10, 15 and 20 (the first estimate's are never published)
                assert spin_until(ros_node, lambda: subs[2].get_publisher_count() > 0, 20.0), proc.output()
                spin_until(ros_node, lambda: False, 0.2)
        def done():
            return (min(len(got["se"]), len(got["eb"]), len(io.msgs["state"]), len(io.msgs["envelope"])) >= 21
                    and len(got["mk"]) >= 4)
        assert spin_until(ros_node, done, 15.0), proc.output()
        states = {a.stamp_ns: a for a in map(mb.unpack_labelled, io.msgs["state"])}
        envs = {a.stamp_ns: a for a in map(mb.unpack_labelled, io.msgs["envelope"])}
        for m in got["se"]:
            r = read_state_estimate(m)
            assert r.labels == states[r.stamp_ns].labels
            np.testing.assert_array_equal(r.x, states[r.stamp_ns].values)
            assert r.P is not None and r.P.shape == (12, 12)
        for m in got["eb"]:
            b = read_error_bounds(m)
            e = envs[b.stamp_ns].values
            assert b.exact_bound == e[3] and b.exact_bound_valid and b.paper_bound == e[2]
            np.testing.assert_array_equal(b.paper_envelope, e[:2])
            assert not b.noise_bound_declared and b.why_invalid == ""
        arr = got["mk"][-1]
        stamp = arr.markers[0].header.stamp.sec * 1_000_000_000 + arr.markers[0].header.stamp.nanosec
        x = states[stamp].values
        spheres = [m for m in arr.markers if m.type == Marker.SPHERE]
        assert len(spheres) == 3
        for k, b in enumerate(mb.bodies(states[stamp].labels)):
            sph = next(m for m in spheres if m.id == k)
            assert (sph.pose.position.x, sph.pose.position.y) == (x[b.p_x], x[b.p_y])
        # the body in view (channel 2: agent2) in its own colour, the others alike
        colours = [(round(m.color.r, 3), round(m.color.g, 3), round(m.color.b, 3)) for m in spheres]
        assert colours[2] != colours[0] == colours[1]
        circles = {m.id: m for m in arr.markers if m.type == Marker.LINE_STRIP and m.action == Marker.ADD}
        assert sorted(circles) == [0, 1, 2]           # the valid exact bound drawn around every body
        bound = envs[stamp].values[3]
        for k, b in enumerate(mb.bodies(states[stamp].labels)):
            radii = [np.hypot(p.x - x[b.p_x], p.y - x[b.p_y]) for p in circles[k].points]
            np.testing.assert_allclose(radii, bound, rtol=1e-9)
    finally:
        proc.stop()
