"""The estimator's optional outputs' writers (odometries, typed, markers, covariance) are serialised at their
first use, not at start-up: the same messages as writers built at once. (Compared decoded: the
serialiser leaves CDR padding bytes as it finds them, so two writers' bytes differ there.)"""

from __future__ import annotations

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray
from switchobs_msgs.msg import ErrorBounds, StateEstimate
from visualization_msgs.msg import MarkerArray

import msg_bridge as mb
from msg_bridge.markers import RawMarkersWriter
from msg_bridge.raw import RawLabelledArrayWriter, RawOdometryBatch
from msg_bridge.typed import ErrorBoundsWriter, RawStateEstimateWriter
from switchobs_ros.estimator import EstimatorNode


def _same(a: bytes, b: bytes, kind: type) -> bool:
    return deserialize_message(bytes(a), kind) == deserialize_message(bytes(b), kind)


def test_optional_writers_are_built_at_first_use_with_the_same_messages(paper_tables, ros_node):
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("noise.measurement_std", value=0.01)])
    try:
        assert est._writers == {}                   # nothing of the optional outputs at start-up
        assert est.pub_markers is None and est.markers_pending      # ~/markers: after the first estimate
        assert len(est.pub_odom) == len(est.bodies) > 0
        rng = np.random.default_rng(3)
        n = est.system.n
        x = rng.normal(size=n)
        G = rng.normal(size=(n, n))
        P = G @ G.T
        env = rng.uniform(0.0, 1.0, size=len(est.env_labels))
        stamp = 1_234_567_890_123
        eager_odom = RawOdometryBatch(est.bodies, est.frame, est.child_frames)
        for a, b in zip(est.w_odom.msgs(x, stamp, P), eager_odom.msgs(x, stamp, P), strict=True):
            assert _same(a, b, Odometry)
        eager_typed = (RawStateEstimateWriter(est.state_labels, est.frame),
                       ErrorBoundsWriter(est.system.N, est.frame, est._noise_declared))
        assert _same(est.w_typed[0].msg(x, stamp, P), eager_typed[0].msg(x, stamp, P), StateEstimate)
        assert _same(serialize_message(est.w_typed[1].msg(env, stamp, True, "", "")),
                     serialize_message(eager_typed[1].msg(env, stamp, True, "", "")), ErrorBounds)
        eager_markers = RawMarkersWriter(est.bodies, est.frame)
        body = est.bodies[1].name
        assert _same(est.w_markers.msg(x, stamp, P, 0.5, body), eager_markers.msg(x, stamp, P, 0.5, body),
                     MarkerArray)
        eager_cov = RawLabelledArrayWriter(mb.covariance_labels(est.state_labels))
        assert _same(est.w_cov.msg(P.ravel(), stamp), eager_cov.msg(P.ravel(), stamp), Float64MultiArray)
        # built once: the same objects at every later use
        assert est.w_odom is est.w_odom and est.w_markers is est.w_markers and est.w_typed is est.w_typed
        assert est.w_cov is est.w_cov
        assert set(est._writers) == {"odom", "typed", "markers", "cov"}
    finally:
        est.destroy_node()


def test_an_optional_writer_that_fails_costs_no_other_estimate(paper_tables, ros_node, monkeypatch):
    """A writer that cannot be built (or write) is counted as the estimate's ``publish`` internal
    error; ``~/state`` of that estimate is out already, and every other estimate of the call is
    published in full."""
    from types import SimpleNamespace

    import switchobs_ros.outputs as outputs

    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"])])
    try:
        monkeypatch.setattr(outputs, "listened", lambda pub: pub is not None)   # as if every output had a subscriber
        est.every.update(markers=2, envelope=1)
        est._create_markers_publisher()                  # as after a first estimate
        calls = []

        def broken(*args):
            calls.append(args)
            raise ValueError("raw message: the sentinels of t0 are found at 2 offsets")

        est._writers["markers"] = SimpleNamespace(msg=broken)
        n = est.system.n
        es = [SimpleNamespace(x_hat=np.full(n, float(i)), stamp_ns=10**9 * (i + 1), P=None, channel=1,
                              envelope=np.full(len(est.env_labels), 0.5)) for i in range(5)]
        before = est.pipeline.rejected[("publish", "internal_error")]
        est._publish_all(es)
        assert est.published["state"] == 5 and est.published["envelope"] == 5
        assert len(calls) == 3                           # estimates 0, 2 and 4 were due on ~/markers
        assert est.pipeline.rejected[("publish", "internal_error")] - before == 3
        assert "t0 are found at 2 offsets" in est.pipeline.last_rejection
    finally:
        est.destroy_node()


def test_the_markers_publisher_is_created_right_after_the_first_estimate(paper_tables, ros_node):
    """No ``~/markers`` publisher before the first estimate; one (MarkerArray, reliable) right after it,
    created once; a system without estimates never creates it."""
    from types import SimpleNamespace

    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"])])
    try:
        assert est.pub_markers is None and est.markers_pending
        assert est.count_publishers("/estimator/markers") == 0
        est._publish_all([])                            # no estimate: nothing created
        assert est.pub_markers is None and est.markers_pending
        n = est.system.n
        e = SimpleNamespace(x_hat=np.zeros(n), stamp_ns=10**9, P=None, channel=1,
                            envelope=np.full(len(est.env_labels), 0.5))
        est._publish_all([e])
        pub = est.pub_markers
        assert pub is not None and not est.markers_pending and est.published["state"] == 1
        assert pub.topic_name == "/estimator/markers" and pub.msg_type is MarkerArray
        assert est.count_publishers("/estimator/markers") == 1
        est._publish_all([e])
        assert est.pub_markers is pub and est.count_publishers("/estimator/markers") == 1
    finally:
        est.destroy_node()

